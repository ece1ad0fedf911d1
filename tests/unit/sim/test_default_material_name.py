"""``--material sim-brushed``: the name results and the page give the simulated rig's default
material selects that material (it was refused as an unknown library name)."""

from __future__ import annotations

import numpy as np
import pytest

from gonio.sim.rig import default_material, resolve_material


def test_the_default_materials_name_selects_it() -> None:
    named = resolve_material("sim-brushed")
    assert named.name == "sim-brushed"  # type: ignore[attr-defined]
    rng = np.random.default_rng(2)
    wi = rng.normal(size=(50, 3))
    wo = rng.normal(size=(50, 3))
    wi[:, 2], wo[:, 2] = np.abs(wi[:, 2]), np.abs(wo[:, 2])  # both above the specimen
    wi /= np.linalg.norm(wi, axis=1, keepdims=True)
    wo /= np.linalg.norm(wo, axis=1, keepdims=True)
    np.testing.assert_array_equal(named.eval(wi, wo), default_material().eval(wi, wo))


def test_an_unknown_name_is_still_refused_with_advice() -> None:
    with pytest.raises(ValueError, match="gonio library list"):
        resolve_material("sim-brushd")
