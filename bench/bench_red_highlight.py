"""Diagnostic: why a red clear-coated paint's reconstructed highlight is cyan
(docs/notes/2026-11-27-red-highlight.md).

A solid paint of sim/spectral.py (a Lambertian pigment under a clear coat, GGX alpha 0.06,
n = 1.5) read through the 31-band spectrometer by the default simulated rig's twelve pairs at
8 stage angles over half a turn, 1 % noise (the reading of ``gonio scan --sim --material
solid-red-paint``), reconstructed on the default basis and compared with its exact table
(``from_function`` of the spectral model) at the coat's mirror peak (``th = 0``, ``td = 30``
degrees: the in-plane peak at an incidence of 30 degrees), just off it (``th = 5``) and in the
diffuse body (``th = 45``): per band (450, 550, 650 nm) and in linear sRGB (D65/10, as the
renderings convert it). Rows:

- the red paint with the defaults, with ``local=None`` and with ``method="vf"``;
- the same coat over other bodies (white, mid grey, black ColorChecker patches);
- ``--mirror-pair``: the red paint with a 13th pair at the first light's mirror direction;
- ``--shared``: an experiment, not gonio's fit: the darkest band reconstructed alone and every
  band as that reconstruction plus the reconstruction of its excess over it (the readings
  minus the darkest band's, clamped at 0).

Usage: ``nice -n 10 .venv/bin/python bench/bench_red_highlight.py [--mirror-pair] [--shared]``
(a few seconds with a warm cache).
"""

from __future__ import annotations

import argparse
import math
from typing import Any

import numpy as np

from gonio.brdf.colour.conditions import ViewingConditions
from gonio.brdf.colour.exportspace import srgb_matrix
from gonio.brdf.reconstruction.basis import Basis, default_basis
from gonio.brdf.reconstruction.reconstruct import pair_cells, reconstruct
from gonio.brdf.reconstruction.samples import NoiseModel, simulate_samples, uniform_stage_angles
from gonio.brdf.tables.metrics import log_rmse
from gonio.brdf.tables.table import BRDFTable, from_function
from gonio.sim import spectral as sp
from gonio.sim.rig import DEFAULT_LIGHTS, DEFAULT_SENSORS

#: (label, th index, td index) of the grid cells compared (5 degree steps).
CELLS = (("peak th0 td30", 0, 6), ("th5 td30", 1, 6), ("body th45 td30", 9, 6))
#: Band indices of 450, 550 and 650 nm among the spectrometer's 31.
BANDS = [5, 15, 25]
#: Other bodies under the same coat: ColorChecker patches.
BODIES = (("white", "white 9.5 (.05 D)"), ("mid grey", "neutral 5 (.70 D)"),
          ("black", "black 2 (1.5 D)"))


def _direction(theta_deg: float, phi_deg: float) -> list[float]:
    t, p = math.radians(theta_deg), math.radians(phi_deg)
    return [math.sin(t) * math.cos(p), math.sin(t) * math.sin(p), math.cos(t)]


def rig_pairs(mirror_pair: bool) -> tuple[np.ndarray, np.ndarray]:
    """(cells, ph_lab) of the default simulated rig's pairs (and the mirror pair if asked)."""
    lights = [_direction(*a) for a in DEFAULT_LIGHTS for _ in DEFAULT_SENSORS]
    sensors = [_direction(*a) for _ in DEFAULT_LIGHTS for a in DEFAULT_SENSORS]
    if mirror_pair:
        lights.append(_direction(45.0, 134.0))
        sensors.append(_direction(45.0, 314.0))
    return pair_cells(np.array(lights), np.array(sensors))


def shared_table(basis: Basis, cells: np.ndarray, ph: np.ndarray, alpha: np.ndarray,
                 vals: np.ndarray, channels: tuple[str, ...]) -> BRDFTable:
    """The ``--shared`` experiment (module docstring)."""
    k = int(np.argmin(vals.sum(axis=(0, 1))))
    ref = reconstruct(basis, cells, ph, alpha, vals[:, :, k:k + 1], channels=("ref",))
    exc = reconstruct(basis, cells, ph, alpha, np.maximum(vals - vals[:, :, k:k + 1], 0.0),
                      channels=channels)
    v = np.asarray(exc.table.values, float) + np.asarray(ref.table.values, float)
    return BRDFTable.trusted(v, channels, "shared")


def compare(label: str, spec: Any, basis: Basis, cells: np.ndarray, ph: np.ndarray,
            shared: bool = False, **kw: Any) -> None:
    """Print truth and reconstruction at :data:`CELLS`, per band and in linear sRGB."""
    alpha = uniform_stage_angles(8, span=math.pi)
    vals = NoiseModel(0.01, seed=4).apply(
        simulate_samples(spec, cells, ph, alpha, noise=NoiseModel(0.0, 0.0)))
    truth = from_function(spec.eval, spec.channels, spec.name)
    rec = reconstruct(basis, cells, ph, alpha, vals, channels=spec.channels, **kw)
    table = shared_table(basis, cells, ph, alpha, vals, spec.channels) if shared else rec.table
    t_all = np.asarray(truth.values, float)
    r_all = np.asarray(table.values, float)
    srgb = srgb_matrix(spec.bands, len(spec.channels), ViewingConditions())
    print(f"\n== {label}  (local_prior {rec.settings.get('local_prior')}, "
          f"log_rmse {log_rmse(table, truth):.4f})")
    for name, i_th, i_td in CELLS:
        t = np.nanmean(t_all[:, :, i_th, i_td, :], axis=(1, 2))
        r = np.nanmean(r_all[:, :, i_th, i_td, :], axis=(1, 2))
        ts, rs = srgb @ t, srgb @ r
        print(f"  {name:15s} 450/550/650 nm truth {np.round(t[BANDS], 3)} rec/truth "
              f"{np.round((r / t)[BANDS], 3)} | sRGB truth {np.round(ts, 3)} rec "
              f"{np.round(rs, 3)} rec/truth {np.round(rs / ts, 3)}")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--mirror-pair", action="store_true")
    ap.add_argument("--shared", action="store_true")
    args = ap.parse_args(argv)
    basis = default_basis()
    cells, ph = rig_pairs(False)
    print("pairs' th (deg):", np.round(np.degrees(cells[:, 0]), 1))
    print("pairs' td (deg):", np.round(np.degrees(cells[:, 1]), 1))
    red = sp.spectral_specimen("solid-red-paint")
    compare("red paint, defaults", red, basis, cells, ph)
    compare("red paint, local=None", red, basis, cells, ph, local=None)
    compare("red paint, method='vf'", red, basis, cells, ph, method="vf")
    for label, patch in BODIES:
        spec = sp.SpectralSpecimen(sp._solid_paint(patch)(), sp.SPECTROMETER_31, label)
        compare(f"{label} body, same coat", spec, basis, cells, ph)
    if args.shared:
        compare("red paint, shared darkest band (experiment)", red, basis, cells, ph,
                shared=True)
        compare("blue paint, shared darkest band (experiment)",
                sp.spectral_specimen("solid-blue-paint"), basis, cells, ph, shared=True)
    if args.mirror_pair:
        cells2, ph2 = rig_pairs(True)
        print("\nmirror pair: th, td, pd (deg)", np.round(np.degrees(cells2[-1]), 1))
        compare("red paint + mirror pair", red, basis, cells2, ph2)
        if args.shared:
            compare("red paint + mirror pair, shared darkest band", red, basis, cells2, ph2,
                    shared=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
