"""Numerical core: pure functions over NumPy arrays. Imports nothing else from gonio.

One subpackage per job; each module's docstring says what it holds.

==================  ===========================================================================
``tables``          the 5 degree half/difference grid (``geometry``), the tabulated BRDF
                    (``table``), the ``.npz`` container (``npzfile``), errors between tables
                    (``metrics``), physical bounds of a table (``bounds``), the pictures'
                    monotone cubic lookup in log (``interpolation``)
``models``          analytic BRDF models (``analytic``), the factored fit (``factored``), the
                    principled-parameter fit (``principled``)
``materials``       where BRDFs come from: synthetic training library (``library``), shipped
                    measured set and the user library (``measured``), ``gonio library import``
                    (``imports``), foreign readers (``merl``, ``rgl``)
``reconstruction``  the linear basis (``basis``), sparse samples to a full BRDF
                    (``reconstruct``), simulated scans and the samples file (``samples``)
``design``          where to put the light/sensor pairs: rig constraints, the condition-number
                    search, pair and product designs, presets, the roughness bound, held-out error
``pictures``        rendered images (``render``), slice previews (``preview``), the standard
                    renderings and their HDR-FLIP (``appearance``)
``colour``          CIE XYZ, CIELAB, flop index and CIEDE2000 at instrument geometries through
                    colour-science; spectral bands, chart calibration of RGB sensors
==================  ===========================================================================

The rooms depend one way: ``tables`` on nothing, ``models`` on ``tables``, ``materials`` on
both, ``reconstruction`` on those, ``design`` on all of them, ``pictures`` and ``colour``
on ``tables``
(an import-linter ``layers`` contract in pyproject.toml checks it). Beside them,
``advice`` holds :class:`~gonio.brdf.advice.AdvisedError`, the base of core errors that name a
setting to change without using the CLI's words for it.

The entry points other tools call can be imported from here as well as from their homes::

    from gonio.brdf import default_basis, design_pairs, get_preset, log_rmse, reconstruct
    from gonio.brdf import simulate_samples

They load on first use, so importing one room (say ``gonio.brdf.tables``) does not pull in
SciPy and the design search.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from gonio.brdf.design.pairs import design_pairs
    from gonio.brdf.design.presets import get_preset
    from gonio.brdf.reconstruction.basis import default_basis
    from gonio.brdf.reconstruction.reconstruct import reconstruct
    from gonio.brdf.reconstruction.samples import simulate_samples
    from gonio.brdf.tables.metrics import log_rmse

# entry point -> the module it lives in
_HOMES = {
    "default_basis": "gonio.brdf.reconstruction.basis",
    "design_pairs": "gonio.brdf.design.pairs",
    "get_preset": "gonio.brdf.design.presets",
    "log_rmse": "gonio.brdf.tables.metrics",
    "reconstruct": "gonio.brdf.reconstruction.reconstruct",
    "simulate_samples": "gonio.brdf.reconstruction.samples",
}

__all__ = [
    "default_basis", "design_pairs", "get_preset", "log_rmse", "reconstruct", "simulate_samples",
]


def __getattr__(name: str) -> Any:
    """Import an entry point from its home on first use (PEP 562)."""
    home = _HOMES.get(name)
    if home is None:
        raise AttributeError(f"module 'gonio.brdf' has no attribute {name!r}")
    value = getattr(importlib.import_module(home), name)
    globals()[name] = value
    return value
