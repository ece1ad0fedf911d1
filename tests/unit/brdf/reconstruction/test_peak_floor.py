"""The self-estimate's floor at the physical peak bound (issue 23 item 4; science.md 7.5).

A polished Ward lobe (alpha 0.06, no diffuse part) read by the default simulated rig's twelve
pairs, none near its mirror direction, reconstructs far above every reading. Its reported
``predicted_log_rmse`` must then be the error the table carries above 1000 times the largest
reading, computed here from the definition with the full metric (``metrics.log_rmse`` of the
table against its capped copy), and the interval's upper end must follow from it.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from gonio.brdf.models import analytic as bm
from gonio.brdf.reconstruction import shipped
from gonio.brdf.reconstruction.basis import Basis
from gonio.brdf.reconstruction.reconstruct import Reconstruction, pair_cells, reconstruct
from gonio.brdf.reconstruction.samples import NoiseModel, simulate_samples, uniform_stage_angles
from gonio.brdf.reconstruction.selfcheck import (
    UPPER_FACTOR,
    UPPER_FACTOR_FLAGGED,
    final_log_rmse,
    widen_log_rmse,
)
from gonio.brdf.tables.bounds import PEAK_RATIO_LIMIT
from gonio.brdf.tables.metrics import log_rmse
from gonio.brdf.tables.table import BRDFTable
from gonio.sim.rig import DEFAULT_LIGHTS, DEFAULT_SENSORS


def _direction(theta_deg: float, phi_deg: float) -> list[float]:
    t, p = math.radians(theta_deg), math.radians(phi_deg)
    return [math.sin(t) * math.cos(p), math.sin(t) * math.sin(p), math.cos(t)]


@pytest.fixture(scope="module")
def scan() -> tuple[Basis, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(basis, cells, ph_lab, stage angles, readings) of the polished lobe on the sim rig."""
    basis = shipped.shipped_basis(shipped.SHIPPED_COMPONENTS)
    assert basis is not None
    lights = np.array([_direction(*d) for d in DEFAULT_LIGHTS for _ in DEFAULT_SENSORS])
    sensors = np.array([_direction(*d) for _ in DEFAULT_LIGHTS for d in DEFAULT_SENSORS])
    cells, ph = pair_cells(lights, sensors)
    alpha = uniform_stage_angles(8, span=math.pi)
    vals = NoiseModel(0.01, seed=3).apply(simulate_samples(bm.Ward(0.06, 0.06, 0.9), cells, ph,
                                                           alpha))
    return basis, cells, ph, alpha, vals


def _excess_by_definition(rec: Reconstruction, vals: np.ndarray) -> float:
    cap = PEAK_RATIO_LIMIT * float(np.nanmax(vals))
    v = np.asarray(rec.table.values, dtype=float)
    assert np.nanmax(v) > cap  # the reconstruction is above the bound: the floor can bind
    return log_rmse(rec.table, BRDFTable.trusted(np.minimum(v, cap), rec.table.channels, "cap"))


def test_the_joint_fit_reports_at_least_the_error_above_the_peak_bound(scan: tuple) -> None:
    basis, cells, ph, alpha, vals = scan
    rec = reconstruct(basis, cells, ph, alpha, vals)
    excess = _excess_by_definition(rec, vals)
    assert rec.peak_excess_log_rmse == pytest.approx(excess, rel=1e-9)
    assert rec.misfit is not None
    before = final_log_rmse(rec.predicted_log_rmse_unwidened, rec.uncovered_share, rec.misfit)
    assert excess > before  # the floor binds on this scan
    assert rec.predicted_log_rmse == pytest.approx(excess, rel=1e-9)
    factor = UPPER_FACTOR_FLAGGED if rec.misfit.flagged else UPPER_FACTOR
    assert rec.predicted_log_rmse_upper == pytest.approx(factor * excess, rel=1e-9)


def test_the_vf_path_has_the_same_floor_and_no_interval(scan: tuple) -> None:
    basis, cells, ph, alpha, vals = scan
    rec = reconstruct(basis, cells, ph, alpha, vals, method="vf")
    excess = _excess_by_definition(rec, vals)
    assert rec.misfit is not None
    before = widen_log_rmse(rec.predicted_log_rmse_unwidened, rec.misfit)
    assert excess > before
    assert rec.predicted_log_rmse == pytest.approx(excess, rel=1e-9)
    assert math.isnan(rec.predicted_log_rmse_upper)



def test_a_misfit_message_names_the_floor_when_the_floor_set_the_estimate() -> None:
    """The misfit's message says the estimate is the peak-bound floor, not that the misfit
    widened it."""
    from gonio.brdf.reconstruction.selfcheck import BasisMisfit

    flagged = BasisMisfit(chi2=400.0, log_misfit=0.12, persistent_pairs=3, n_pairs=10,
                          n_angles=8)
    text = flagged.message(0.05, 0.4, floored=True) or ""
    assert "is 0.400, the error the table carries above the physical peak bound" in text
    assert "was widened from" not in text
    assert "was widened from 0.050 to 0.400" in (flagged.message(0.05, 0.4) or "")
