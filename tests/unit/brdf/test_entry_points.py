"""The entry points gonio.brdf offers at its top level are the functions of their homes."""

from __future__ import annotations

import subprocess
import sys

import pytest

import gonio.brdf
from gonio.brdf.design.pairs import design_pairs
from gonio.brdf.design.presets import get_preset
from gonio.brdf.reconstruction.basis import default_basis
from gonio.brdf.reconstruction.reconstruct import reconstruct
from gonio.brdf.reconstruction.samples import simulate_samples
from gonio.brdf.tables.metrics import log_rmse


def test_top_level_names_are_the_homes_functions() -> None:
    from gonio.brdf import default_basis as a
    from gonio.brdf import design_pairs as b
    from gonio.brdf import get_preset as c
    from gonio.brdf import log_rmse as d
    from gonio.brdf import reconstruct as e
    from gonio.brdf import simulate_samples as f

    assert (a, b, c, d, e, f) == (
        default_basis, design_pairs, get_preset, log_rmse, reconstruct, simulate_samples
    )
    assert sorted(gonio.brdf.__all__) == sorted(
        ["default_basis", "design_pairs", "get_preset", "log_rmse", "reconstruct",
         "simulate_samples"]
    )


def test_unknown_name_is_an_attribute_error() -> None:
    with pytest.raises(AttributeError, match="no attribute 'geometry'"):
        _ = gonio.brdf.geometry  # the old flat module moved to gonio.brdf.tables


def test_one_room_loads_without_the_others() -> None:
    # Importing the grid must not load the solver (SciPy) or the design search: the entry
    # points load on first use.
    code = (
        "import sys; import gonio.brdf.tables.geometry; "
        "print(sorted(m for m in sys.modules if m.startswith(('scipy', 'gonio.brdf.design', "
        "'gonio.brdf.reconstruction'))))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, timeout=120).stdout
    assert out.strip() == "[]"
