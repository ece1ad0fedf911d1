"""The parametric tilt (gonio.brdf.reconstruction.tilt): rotation, the normal map's factor,
the table through a lean, and the lean recovered from readings."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest

from gonio.brdf.models import analytic as bm
from gonio.brdf.reconstruction import shipped
from gonio.brdf.reconstruction.basis import Basis
from gonio.brdf.reconstruction.errors import ReconstructionError
from gonio.brdf.reconstruction.reconstruct import reconstruct
from gonio.brdf.reconstruction.samples import NoiseModel, simulate_samples, uniform_stage_angles
from gonio.brdf.reconstruction.tilt import (
    fit_tilt,
    map_readings,
    pair_rms,
    tilt_decision,
    tilt_factor,
    tilted_table,
)
from gonio.brdf.tables import geometry as geo
from gonio.brdf.tables.table import BRDFTable


def _normal(t: float, b: float) -> np.ndarray:
    return np.array([np.sin(t) * np.cos(b), np.sin(t) * np.sin(b), np.cos(t)])


@pytest.mark.parametrize(("t", "b"), [(0.3, 1.0), (0.1, 4.0), (0.5, -2.0)])
def test_the_rotation_takes_the_leaning_normal_to_z(t: float, b: float) -> None:
    R = bm.facet_rotation(t, b)
    np.testing.assert_allclose(R @ _normal(t, b), [0.0, 0.0, 1.0], atol=1e-12)
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(R) == pytest.approx(1.0)
    # The shortest rotation: its axis is level and at right angles to the lean.
    axis = np.array([np.sin(b), -np.cos(b), 0.0])
    np.testing.assert_allclose(R @ axis, axis, atol=1e-12)


def test_no_lean_is_the_identity_and_a_factor_of_one() -> None:
    np.testing.assert_array_equal(bm.facet_rotation(0.0, 2.0), np.eye(3))
    wo = geo.spherical_to_direction(np.array([0.1, 0.7, 1.3]), np.array([0.0, 2.0, 4.0]))
    np.testing.assert_allclose(tilt_factor(np.eye(3), wo), 1.0)


def test_the_bare_factor_matches_the_analytic_normal_map() -> None:
    """Tilted(masking="none") is the normal map written out independently in analytic.py."""
    inner = bm.GGX(0.15, 0.3)
    t, b = np.deg2rad(18.0), np.deg2rad(130.0)
    tilted = bm.Tilted(inner, t, b, masking="none")
    rng = np.random.default_rng(4)
    wi = geo.spherical_to_direction(rng.uniform(0, 1.3, 300), rng.uniform(0, 2 * np.pi, 300))
    wo = geo.spherical_to_direction(rng.uniform(0, 1.3, 300), rng.uniform(0, 2 * np.pi, 300))
    R = bm.facet_rotation(t, b)
    ri, ro = wi @ R.T, wo @ R.T
    up = (ri[:, 2] > 0) & (ro[:, 2] > 0)
    model = np.zeros((300, 3))
    model[up] = inner.eval(ri[up], ro[up]) * tilt_factor(R, wo[up], terminator=False)[:, None]
    np.testing.assert_allclose(model, tilted.eval(wi, wo), rtol=1e-9, atol=1e-12)


def test_the_terminator_term_follows_estevez() -> None:
    """Estevez et al. 2019: 2 / (1 + sqrt(1 + a2 tan^2 theta_o)), a2 = min(tan^2 t / 8, 1);
    worked by hand for t = 20 deg, theta_o = 80 deg, wo in the plane of the lean."""
    t = np.deg2rad(20.0)
    R = bm.facet_rotation(t, 0.0)
    wo = geo.spherical_to_direction(np.deg2rad(80.0), 0.0)
    a2 = np.tan(t) ** 2 / 8  # 0.016559
    expected_shadow = 2 / (1 + np.sqrt(1 + a2 * np.tan(np.deg2rad(80.0)) ** 2))  # 0.8353
    cos_in_lean = np.cos(np.deg2rad(60.0))  # 80 deg from z, leaning towards it by 20
    expected = cos_in_lean / np.cos(np.deg2rad(80.0)) * expected_shadow
    assert float(tilt_factor(R, wo)) == pytest.approx(expected, rel=1e-9)
    below = geo.spherical_to_direction(np.deg2rad(80.0), np.pi)  # 100 deg from the lean
    assert float(tilt_factor(R, below)) == 0.0


def _table(model: bm.BRDFModel) -> BRDFTable:
    vals = np.asarray(bm.tabulate_valid(model), dtype=np.float32)
    if vals.shape[1] == 1:
        vals = np.repeat(vals, geo.N_PH, axis=1)
    full = np.full((3, geo.N_PH, *geo.SLICE_SHAPE), np.nan, dtype=np.float32)
    full[:, :, geo.valid_mask()] = vals
    return BRDFTable(full, ("R", "G", "B"), "t")


def test_a_table_through_no_lean_is_the_table() -> None:
    g = _table(bm.GGX(0.3, 0.3))
    out = tilted_table(g, 0.0, 0.0)
    np.testing.assert_allclose(out.values, g.values, rtol=1e-4, atol=1e-6)


def test_a_table_through_a_lean_matches_the_model_through_it() -> None:
    """A smooth lobe's table seen through a lean against the analytic normal map (with the
    terminator term) evaluated at the grid's cells: close in log_rmse, and far closer than to
    the bare normal map. Not exact: cells whose mapped directions fall between the grid's last
    valid nodes and the horizon have no valid neighbour and are 0 (a Lambert lobe alone comes
    out at 0.04, a GGX lobe alone at 0.04, their sum at 0.063)."""
    from gonio.brdf.tables import metrics

    inner = bm.LobeSum((bm.Lambert((0.4, 0.3, 0.2)), bm.GGX(0.35, 0.35)))
    t, b = np.deg2rad(15.0), np.deg2rad(70.0)
    out = tilted_table(_table(inner), t, b)
    truth = _table(_Terminated(bm.Tilted(inner, t, b, masking="none"), t, b))
    bare = _table(bm.Tilted(inner, t, b, masking="none"))
    err = metrics.log_rmse(out, truth)
    assert err < 0.07
    assert err < 0.5 * metrics.log_rmse(out, bare)


@dataclass(frozen=True)
class _Terminated:
    """A renderer's normal map: the bare one times Estevez et al.'s term (test_the_terminator
    states it)."""

    model: bm.BRDFModel
    t: float
    b: float
    channels: tuple[str, ...] = ("R", "G", "B")

    def eval(self, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        o = np.asarray(wo, dtype=float)
        a2 = min(np.tan(self.t) ** 2 / 8, 1.0)
        with np.errstate(divide="ignore", invalid="ignore"):
            tan2 = (1 - o[..., 2] ** 2) / o[..., 2] ** 2
            s = np.where(o[..., 2] > 0, 2 / (1 + np.sqrt(1 + a2 * tan2)), 0.0)
        return np.asarray(self.model.eval(wi, wo)) * s[..., None]

    def isotropic(self) -> bool:
        return False


@pytest.fixture(scope="module")
def basis() -> Basis:
    b = shipped.shipped_basis(shipped.SHIPPED_COMPONENTS)
    assert b is not None
    return b


def _scan(model: object, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    n = 10
    cells = np.stack([np.deg2rad(rng.uniform(5, 45, n)), np.deg2rad(rng.uniform(5, 50, n)),
                      np.deg2rad(rng.uniform(0, 180, n))], axis=1)
    ph = rng.uniform(0, 2 * np.pi, n)
    alpha = uniform_stage_angles(12)
    vals = simulate_samples(model, cells, ph, alpha, noise=NoiseModel(0.01, seed=seed))
    return cells, ph, alpha, vals


SMALL_GRID = {"tilts_deg": (0.0, 10.0, 20.0), "azimuths_deg": (0.0, 60.0, 120.0, 180.0, 240.0,
                                                                 300.0)}


def test_a_lean_is_recovered_from_the_readings(basis: Basis) -> None:
    inner = bm.LobeSum((bm.Lambert((0.3, 0.2, 0.1)), bm.GGX(0.12, 0.12)))
    t, b = np.deg2rad(15.0), np.deg2rad(80.0)
    cells, ph, alpha, vals = _scan(_Terminated(bm.Tilted(inner, t, b, masking="none"), t, b), 3)
    fit = fit_tilt(basis, cells, ph, alpha, vals, **SMALL_GRID, reference=basis)
    assert abs(np.rad2deg(fit.tilt) - 15.0) <= 4.0
    # A true lean of 15 deg: the rule takes it over the plain fit, on most pairs.
    assert fit.accepted and fit.n_pairs == 10 and fit.pairs_improved >= 7
    assert fit.settings["tilt_accepted"] is True
    assert abs((np.rad2deg(fit.azimuth) - 80.0 + 180) % 360 - 180) <= 20.0
    assert fit.holdout_error < fit.plain_holdout_error
    assert fit.settings["tilt_deg"] == pytest.approx(np.rad2deg(fit.tilt), abs=1e-3)
    assert fit.table.values.shape == (3, geo.N_PH, *geo.SLICE_SHAPE)


def test_an_untilted_specimen_keeps_no_lean(basis: Basis) -> None:
    model = bm.Rotated(bm.GGX(0.1, 0.35), 0.7)
    cells, ph, alpha, vals = _scan(model, 5)
    fit = fit_tilt(basis, cells, ph, alpha, vals, **SMALL_GRID, reference=basis)
    assert fit.tilt == 0.0
    assert not fit.accepted and "tilt 0" in fit.decision
    assert fit.holdout_error == fit.plain_holdout_error
    # No lean: the plain joint fit of the scan as read, unchanged.
    plain = reconstruct(basis, cells, ph, alpha, vals)
    np.testing.assert_array_equal(fit.table.values, plain.table.values)


def test_readings_below_the_lean_leave_the_fit() -> None:
    cells = np.array([[np.deg2rad(40.0), np.deg2rad(40.0), 0.0]])
    ph = np.zeros(1)
    alpha = np.deg2rad([0.0, 180.0])
    vals = np.ones((1, 2, 3))
    m = map_readings(cells, ph, alpha, vals, np.deg2rad(30.0), 0.0)
    # The light is 80 deg from z towards +x at stage 0 and towards -x at stage 180, the
    # sensor at the normal: a 30 deg lean towards +x puts the light at 50 deg, then at 110.
    np.testing.assert_array_equal(m.keep, [[True, False]])
    assert m.values.shape == (int(m.keep.sum()), 3)


def test_pair_rms_is_the_rms_over_each_pairs_readings() -> None:
    e = np.zeros((2, 2, 2))
    e[0] = [[3.0, 0.0], [4.0, 0.0]]
    e[1] = [[1.0, 1.0], [1.0, 1.0]]
    # Pair 0: sqrt((9 + 16) / 4) = 2.5; pair 1: 1.
    np.testing.assert_allclose(pair_rms(e), [2.5, 1.0])


def _errors(per_pair: list[float]) -> np.ndarray:
    """(n, 3, 1) held-out errors whose per-pair RMS is ``per_pair``."""
    return np.broadcast_to(np.asarray(per_pair, dtype=float)[:, None, None], (len(per_pair), 3, 1))


def test_the_rule_counts_pairs_not_the_pooled_error() -> None:
    ref = _errors([0.1] * 10)
    # Lower on 7 of 10 pairs: 7 >= ceil(0.7 * 10), accepted.
    ok, better, why = tilt_decision(_errors([0.05] * 7 + [0.2] * 3), ref, 0.2)
    assert (ok, better) == (True, 7) and "7 of 10" in why
    # Lower on 6 of 10: rejected, although the pooled error is lower (6 * 0.0025 + 4 * 0.0121
    # = 0.0634 < 0.1 = 10 * 0.01).
    tilt = _errors([0.05] * 6 + [0.11] * 4)
    assert np.mean(tilt**2) < np.mean(ref**2)
    ok, better, why = tilt_decision(tilt, ref, 0.2)
    assert (ok, better) == (False, 6) and "fewer than 7" in why
    # A lean that wins the pooled error on three pairs and loses the other seven (the choice
    # set's misplaced lean): 3 * 0 + 7 * 0.0121 = 0.0847 < 0.1 pooled, rejected.
    ok, better, _ = tilt_decision(_errors([0.0] * 3 + [0.11] * 7), ref, 0.2)
    assert (ok, better) == (False, 3)


def test_the_rule_refuses_what_it_cannot_judge() -> None:
    ref = _errors([0.1] * 10)
    better = _errors([0.01] * 10)
    assert tilt_decision(better, ref, 0.0)[0] is False  # no lean
    assert tilt_decision(None, ref, 0.2)[0] is False
    assert tilt_decision(better, None, 0.2)[0] is False
    ok, n, why = tilt_decision(_errors([0.01] * 4), _errors([0.1] * 4), 0.2)
    assert (ok, n) == (False, 4) and "too few" in why
    with pytest.raises(ReconstructionError, match="shapes"):
        tilt_decision(_errors([0.01] * 5), _errors([0.1] * 6), 0.2)


def test_refine_around_narrows_to_the_minimum_of_a_bowl_within_its_last_steps() -> None:
    """Two rounds of 3 x 3 around the coarse best, the steps halved: on a smooth bowl the
    lean found is the grid point of the last round's steps nearest the true minimum."""
    from gonio.brdf.reconstruction.tilt import refine_around

    t0, b0 = 12.3, 47.0  # the bowl's minimum, off every grid

    tried: dict[tuple[float, float], float] = {}

    def score(t: float, b: float) -> float:
        tried[(t, b)] = (t - t0) ** 2 + ((b - b0) / 4.0) ** 2
        return tried[(t, b)]

    for t in (0.0, 5.0, 10.0, 15.0, 20.0):
        for b in range(0, 360, 30):
            score(t, float(b))
    assert min(tried, key=tried.__getitem__) == (10.0, 60.0)  # the coarse best
    t, b = refine_around(score, tried, steps_deg=(2.5, 10.0))
    # Steps 2.5 / 10, then 1.25 / 5: from (10, 60) to (12.5, 50), then (12.5, 45) at most
    # 1.25 / 5 from the truth's (12.3, 47).
    assert (t, b) == (12.5, 45.0)
    assert abs(t - t0) <= 1.25 and abs(b - b0) <= 5.0
    # No tilt at the coarse best: nothing to refine.
    flat = {(0.0, 0.0): 0.0, (5.0, 0.0): 1.0}
    assert refine_around(lambda t, b: 9.0, flat) == (0.0, 0.0)
