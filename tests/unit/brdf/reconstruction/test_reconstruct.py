"""Tests of the sparse reconstruction (math.md 5)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.interpolate import PchipInterpolator
from threadpoolctl import threadpool_info, threadpool_limits

from gonio.brdf.reconstruction.basis import Basis, inverse_remap, row_weight
from gonio.brdf.reconstruction.reconstruct import (
    CV_ERROR_SCALES,
    ReconstructionError,
    _objective,
    cv_error_scale,
    half_turn_scan,
    loo_predictions,
    one_blas_thread,
    pair_cells,
    reconstruct,
    resample_to_slices,
    slices_at_stage_angles,
    solve_closed,
    solve_iterative,
)
from gonio.brdf.reconstruction.samples import NoiseModel, simulate_samples, uniform_stage_angles
from gonio.brdf.tables import geometry as geo
from gonio.brdf.tables import metrics
from tests.unit.brdf.reconstruction.test_basis import small_basis, small_library


def grid_pairs(n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """``n`` random valid grid cells (n, 3) and lab azimuths (n,) on the 5 degree grid."""
    rng = np.random.default_rng(seed)
    th, td, pd = geo.grid_angles()
    idx = rng.choice(np.flatnonzero(geo.valid_mask().ravel()), n, replace=False)
    cells = np.stack([th.ravel()[idx], td.ravel()[idx], pd.ravel()[idx]], axis=1)
    ph = geo.PH_GRID[rng.integers(0, geo.N_PH, n)]
    return cells, ph


def random_basis(k: int, seed: int = 0) -> Basis:
    rng = np.random.default_rng(seed)
    valid = geo.valid_mask().ravel()
    Q = rng.standard_normal((geo.N_ROWS, k)) * np.linspace(3, 0.5, k)
    f_med = rng.uniform(0.05, 2.0, geo.N_ROWS)
    mu = rng.normal(0, 0.3, geo.N_ROWS)
    return Basis(Q, np.linspace(3, 0.5, k), f_med * valid, mu * valid, valid)


# ---------------------------------------------------------------------------- solvers
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_closed_form_and_iterative_agree(seed: int) -> None:
    rng = np.random.default_rng(seed)
    n, k, s = int(rng.integers(5, 30)), int(rng.integers(3, 12)), int(rng.integers(10, 40))
    Qt = rng.standard_normal((n, k))
    Qs = rng.standard_normal((s, k))
    Y = rng.standard_normal((n, geo.N_PH))
    eta, lam = float(rng.uniform(0.1, 50)), float(rng.uniform(0.01, 5))
    c_closed = solve_closed(Y, Qt, Qs, eta, lam)
    c_iter = solve_iterative(Y, Qt, Qs, eta, lam)
    e_closed = _objective(c_closed, Y, Qt, Qs, eta, lam)
    e_iter = _objective(c_iter, Y, Qt, Qs, eta, lam)
    assert e_closed <= e_iter * (1 + 1e-9)
    assert e_iter == pytest.approx(e_closed, rel=1e-8)
    np.testing.assert_allclose(c_iter, c_closed, rtol=1e-5, atol=1e-6 * np.abs(c_closed).max())


def test_closed_form_is_a_stationary_point() -> None:
    """The gradient of Eq. 5 (V&F App. A) vanishes at the closed-form solution."""
    rng = np.random.default_rng(7)
    Qt, Qs = rng.standard_normal((12, 6)), rng.standard_normal((30, 6))
    Y = rng.standard_normal((12, geo.N_PH))
    eta, lam = 40.0, 0.1
    C = solve_closed(Y, Qt, Qs, eta, lam)
    M = np.eye(geo.N_PH) - 1.0 / geo.N_PH
    grad = -2 * Qt.T @ Y + 2 * Qt.T @ Qt @ C + 2 * eta * C + 2 * lam * Qs.T @ Qs @ C @ M
    assert np.abs(grad).max() < 1e-9 * np.abs(Qt.T @ Y).max()


def test_reconstruct_solvers_agree_end_to_end() -> None:
    b = small_basis()
    cells, ph = grid_pairs(10, seed=3)
    alpha = uniform_stage_angles(8)
    vals = simulate_samples(small_library()[0], cells, ph, alpha)
    a = reconstruct(b, cells, ph, alpha, vals, method="vf")
    c = reconstruct(b, cells, ph, alpha, vals, method="vf", solver="iterative")
    scale = np.abs(a.coefficients).max()
    np.testing.assert_allclose(c.coefficients, a.coefficients, atol=1e-5 * scale)
    assert a.settings["solver"] == "closed" and c.settings["solver"] == "iterative"


# ---------------------------------------------------------------------------- exact recovery
def _table_from_coefficients(b: Basis, C: np.ndarray) -> np.ndarray:
    """(72, N_ROWS) BRDF values that lie exactly in the span of ``b`` (NaN at invalid rows)."""
    X = (b.Q @ C).T + b.mu
    with np.errstate(invalid="ignore"):
        out = inverse_remap(X, b.f_med, row_weight(b.eps), b.eps)
    return np.where(b.valid, out, np.nan)


def test_exact_recovery_in_the_span_all_slices_measured() -> None:
    b = random_basis(6, seed=1)
    rng = np.random.default_rng(5)
    C_true = 0.05 * rng.standard_normal((6, geo.N_PH))
    truth = _table_from_coefficients(b, C_true)
    cells, ph = grid_pairs(20, seed=4)
    rows = geo.flat_row(*(np.rint(cells / geo.STEP).astype(int).T))
    alpha = geo.PH_GRID.copy()  # every slice measured: PCHIP is exact at its nodes
    # Pair q at stage angle alpha sees slice ph_q - alpha.
    k = np.rint(np.mod(ph[:, None] - alpha[None, :], 2 * np.pi) / geo.STEP).astype(int) % 72
    vals = truth[k, rows[:, None]][..., None]
    assert np.all(vals > 0), "test set-up: the synthetic BRDF must be positive"
    rec = reconstruct(b, cells, ph, alpha, vals, channels=("Y",), eta=1e-12, lam=0.0,
                      method="vf")
    np.testing.assert_allclose(rec.coefficients[0], C_true, atol=1e-7)
    got = rec.table.values[0].reshape(geo.N_PH, geo.N_ROWS)[:, b.valid]
    # The random basis dips below 0 at a few unsampled cells; the output is clamped there.
    np.testing.assert_allclose(got, np.maximum(truth[:, b.valid], 0.0), rtol=1e-6, atol=1e-9)
    assert rec.rel_sample_error < 1e-6


def test_exact_recovery_of_an_isotropic_material_from_few_rotations() -> None:
    """Identical slices are constant in ph: PCHIP reproduces them and the lam term is 0."""
    b = random_basis(5, seed=2)
    rng = np.random.default_rng(6)
    c = 0.1 * rng.standard_normal(5)
    truth = _table_from_coefficients(b, np.repeat(c[:, None], geo.N_PH, axis=1))
    cells, ph = grid_pairs(12, seed=8)
    rows = geo.flat_row(*(np.rint(cells / geo.STEP).astype(int).T))
    alpha = np.deg2rad([0.0, 50.0, 110.0, 250.0])  # irregular, any order
    vals = np.repeat(truth[0, rows][:, None, None], alpha.size, axis=1)
    rec = reconstruct(b, cells, ph, alpha, vals, channels=("Y",), eta=1e-12, lam=5.0,
                      method="vf")
    np.testing.assert_allclose(rec.coefficients[0], c[:, None] * np.ones(72), atol=1e-7)


# ---------------------------------------------------------------------------- step 1
def test_periodic_resampling_reproduces_samples_and_wraps() -> None:
    alpha = np.deg2rad([350.0, 10.0, 90.0, 200.0])  # unsorted, crosses 0
    ph = np.deg2rad([30.0])
    vals = np.array([[[1.0], [2.0], [5.0], [3.0]]])
    out = resample_to_slices(ph, alpha, vals)[0, :, 0]
    # Slice ph_lab - alpha: 350 -> 40 deg (index 8), 10 -> 20 deg (4), 90 -> 300 (60), ...
    for a, v in zip([350.0, 10.0, 90.0, 200.0], [1.0, 2.0, 5.0, 3.0], strict=True):
        assert out[int(((30.0 - a) % 360) / 5)] == pytest.approx(v)
    # PCHIP does not overshoot the data, which keeps non-negative samples non-negative.
    assert out.min() >= 1.0 - 1e-12 and out.max() <= 5.0 + 1e-12
    # The wrapped interval between 10 and 350 deg (slices 20..40 deg) stays between 1 and 2.
    between = out[4:9]
    assert np.all((between >= 1 - 1e-12) & (between <= 2 + 1e-12))


def _reference_resample(ph: np.ndarray, alpha: np.ndarray, vals: np.ndarray) -> np.ndarray:
    """Per-pair scipy PCHIP over three periods of the stage angle (the plain construction)."""
    a = np.mod(alpha, 2 * np.pi)
    o = np.argsort(a)
    x = np.concatenate([a[o] - 2 * np.pi, a[o], a[o] + 2 * np.pi])
    out = []
    for q in range(ph.size):
        f = PchipInterpolator(x, np.concatenate([vals[q, o]] * 3), axis=0)
        out.append(f(np.mod(ph[q] - geo.PH_GRID, 2 * np.pi)))
    return np.stack(out)


def test_shared_node_resampling_matches_per_pair_interpolants() -> None:
    rng = np.random.default_rng(4)
    ph = rng.uniform(-1, 8, 9)
    alpha = rng.uniform(-4, 10, 7)
    vals = rng.uniform(0, 3, (9, 7, 2))
    np.testing.assert_allclose(
        resample_to_slices(ph, alpha, vals), _reference_resample(ph, alpha, vals), atol=1e-12
    )


def test_slices_back_at_grid_stage_angles_are_exact() -> None:
    """Stage angles on the 5 degree grid hit slice nodes: the round trip returns the samples."""
    rng = np.random.default_rng(5)
    ph = geo.PH_GRID[rng.integers(0, 72, 6)]
    alpha = geo.PH_GRID[rng.choice(72, 10, replace=False)] + 2 * np.pi * rng.integers(-1, 2, 10)
    vals = rng.uniform(0, 1, (6, 10, 3))
    back = slices_at_stage_angles(ph, alpha, resample_to_slices(ph, alpha, vals))
    np.testing.assert_allclose(back, vals, atol=1e-12)


def test_single_rotation_gives_constant_slices() -> None:
    out = resample_to_slices(np.array([0.3]), np.array([1.0]), np.array([[[0.7, 0.2]]]))
    np.testing.assert_allclose(out[0], np.tile([0.7, 0.2], (72, 1)))


# ---------------------------------------------------------------------------- error estimate
def test_loo_predictions_equal_refits_without_each_pair() -> None:
    rng = np.random.default_rng(9)
    n, k = 11, 5
    Qt, Qs = rng.standard_normal((n, k)), rng.standard_normal((20, k))
    Y = rng.standard_normal((n, geo.N_PH, 2))
    eta, lam = 0.7, 0.3
    loo = loo_predictions(Y, Qt, Qs, eta, lam)
    for q in range(n):
        keep = np.arange(n) != q
        C = solve_closed(Y[keep], Qt[keep], Qs, eta, lam)  # (K, 72, 2)
        np.testing.assert_allclose(loo[q], np.tensordot(Qt[q], C, axes=1), atol=1e-10)


def test_loo_is_undefined_when_a_pair_determines_its_own_coefficients() -> None:
    rng = np.random.default_rng(1)
    Qt = rng.standard_normal((4, 4))  # n = K and eta = 0: each pair is fitted exactly
    assert np.isnan(loo_predictions(rng.standard_normal((4, 72)), Qt, Qt, 0.0, 0.0)).all()


def _in_span_scan(
    b: Basis, n: int, seed: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Cells, ph_lab, stage angles (all 72 slices) and exact samples (n, 72, 1) of a BRDF in
    the span of ``b``."""
    rng = np.random.default_rng(seed)
    truth = _table_from_coefficients(b, 0.05 * rng.standard_normal((b.K, geo.N_PH)))
    cells, ph = grid_pairs(n, seed=seed)
    rows = geo.flat_row(*(np.rint(cells / geo.STEP).astype(int).T))
    alpha = geo.PH_GRID.copy()
    k = np.rint(np.mod(ph[:, None] - alpha[None, :], 2 * np.pi) / geo.STEP).astype(int) % 72
    vals = truth[k, rows[:, None]][..., None]
    assert np.all(vals > 0), "test set-up: the synthetic BRDF must be positive"
    return cells, ph, alpha, vals


def test_cv_error_is_near_zero_for_data_in_the_span() -> None:
    b = random_basis(6, seed=1)
    cells, ph, alpha, vals = _in_span_scan(b, 20, seed=5)
    rec = reconstruct(b, cells, ph, alpha, vals, channels=("Y",), eta=1e-12, lam=0.0,
                      method="vf")
    assert rec.cv_sample_error < 1e-6
    assert rec.predicted_error == pytest.approx(cv_error_scale(20) * rec.cv_sample_error)


@pytest.mark.parametrize("sigma", [0.02, 0.08])
def test_cv_error_tracks_the_noise_level(sigma: float) -> None:
    """In-span data with relative noise sigma: a pair left out is predicted from the others
    up to its own noise, so the CV error is about E|N| sigma = sqrt(2 / pi) sigma, while the
    in-sample error is smaller (the fit absorbs part of each pair's noise)."""
    b = random_basis(4, seed=3)
    cells, ph, alpha, clean = _in_span_scan(b, 60, seed=6)
    noise = np.random.default_rng(2).standard_normal(clean.shape)
    vals = clean * (1 + sigma * noise)
    rec = reconstruct(b, cells, ph, alpha, vals, channels=("Y",), eta=1e-9, lam=0.0,
                      method="vf")
    expected = np.sqrt(2 / np.pi) * sigma
    assert 0.85 * expected < rec.cv_sample_error < 1.25 * expected
    assert rec.rel_sample_error < rec.cv_sample_error


def test_cv_error_is_nan_when_undefined() -> None:
    b = random_basis(6, seed=1)
    cells, ph, alpha, vals = _in_span_scan(b, 6, seed=4)
    rec = reconstruct(b, cells, ph, alpha, vals, channels=("Y",), eta=0.0, lam=0.0,
                      method="vf")
    assert np.isnan(rec.cv_sample_error) and np.isnan(rec.predicted_error)
    assert rec.rel_sample_error < 1e-6  # the fit itself is fine: n = K interpolates


def test_cv_scale_interpolates_in_log_pairs_and_holds_at_the_ends() -> None:
    (n0, s0), (n1, s1) = CV_ERROR_SCALES[0], CV_ERROR_SCALES[1]
    assert cv_error_scale(n0) == pytest.approx(s0)
    assert cv_error_scale(1) == pytest.approx(s0)
    assert cv_error_scale(10_000) == pytest.approx(CV_ERROR_SCALES[-1][1])
    mid = round(float(np.sqrt(n0 * n1)))
    t = np.log(mid / n0) / np.log(n1 / n0)
    assert cv_error_scale(mid) == pytest.approx(s0 ** (1 - t) * s1**t)


def test_blas_runs_on_one_thread_inside_the_limit() -> None:
    def blas_threads() -> list[int]:
        return [i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"]

    # Two threads outside, as on an idle 2-core machine (a parallel test worker runs on one:
    # tests/conftest.py), so the limit and its lifting are both seen.
    with threadpool_limits(limits=2, user_api="blas"):
        before = blas_threads()
        assert all(t == 2 for t in before)
        with one_blas_thread():
            assert all(t == 1 for t in blas_threads())
        assert blas_threads() == before


# ---------------------------------------------------------------------------- quality
def test_held_out_material_is_reconstructed_well() -> None:
    b = small_basis()
    ref = small_library()[0]
    cells, ph = grid_pairs(20, seed=11)
    alpha = uniform_stage_angles(12)
    vals = simulate_samples(ref, cells, ph, alpha, noise=NoiseModel(0.01, seed=3))
    rec = reconstruct(b, cells, ph, alpha, vals, name="held-out")
    assert rec.table.name == "held-out"
    assert rec.table.values.shape == (3, *geo.TABLE_SHAPE)
    assert np.nanmin(rec.table.values) >= 0
    assert rec.estimated_error == pytest.approx(0.8 * rec.rel_sample_error)
    assert 0 < rec.rel_sample_error < 0.2
    # Predicting a pair without it is harder than fitting it.
    assert rec.rel_sample_error < rec.cv_sample_error < 1.0
    assert rec.predicted_error == pytest.approx(cv_error_scale(20) * rec.cv_sample_error)
    # Far better than the library median as a guess.
    med = np.broadcast_to(b.f_med.reshape(geo.SLICE_SHAPE), ref.values.shape)
    assert metrics.log_rmse(rec.table, ref) < 0.5 * metrics.log_rmse(med, ref)
    assert metrics.log_psnr(rec.table, ref) > 25.0


def test_n_components_truncates() -> None:
    b = small_basis()
    cells, ph = grid_pairs(8)
    alpha = uniform_stage_angles(4)
    vals = simulate_samples(small_library()[0], cells, ph, alpha)
    rec = reconstruct(b, cells, ph, alpha, vals, n_components=5)
    assert rec.coefficients.shape == (3, 5, 72) and rec.settings["K"] == 5
    with pytest.raises(ReconstructionError, match="cannot keep"):
        reconstruct(b, cells, ph, alpha, vals, n_components=b.K + 1)


def test_off_grid_pairs_from_lab_directions() -> None:
    b = small_basis()
    rng = np.random.default_rng(2)
    ti, tv = rng.uniform(0.1, 1.2, 10), rng.uniform(0.1, 1.2, 10)
    pi_, pv = rng.uniform(0, 2 * np.pi, 10), rng.uniform(0, 2 * np.pi, 10)
    light = geo.spherical_to_direction(ti, pi_)
    sensor = geo.spherical_to_direction(tv, pv)
    cells, ph = pair_cells(light, sensor)
    th, ph2, td, pd = geo.directions_to_half_diff(light, sensor)
    np.testing.assert_allclose(cells, np.stack([th, td, pd], 1))
    np.testing.assert_allclose(ph, ph2)
    # The cells reproduce the directions (up to the pd reciprocity swap).
    wi, wo = geo.half_diff_to_directions(cells[:, 0], ph, cells[:, 1], cells[:, 2])
    same = np.isclose(wi, light, atol=1e-9).all(1) & np.isclose(wo, sensor, atol=1e-9).all(1)
    swap = np.isclose(wi, sensor, atol=1e-9).all(1) & np.isclose(wo, light, atol=1e-9).all(1)
    assert np.all(same | swap)
    alpha = uniform_stage_angles(6)
    vals = simulate_samples(small_library()[0], cells, ph, alpha)
    rec = reconstruct(b, cells, ph, alpha, vals)
    assert np.isfinite(rec.rel_sample_error)


# ---------------------------------------------------------------------------- bad input
def _good() -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    cells, ph = grid_pairs(6)
    alpha = uniform_stage_angles(4)
    return cells, ph, alpha, np.full((6, 4, 3), 0.2)


@pytest.mark.parametrize(
    ("mutate", "match"),
    [
        (lambda c, p, a, v: (c, p, a, np.where(np.arange(4)[None, :, None] == 1, np.nan, v)),
         "NaN"),
        (lambda c, p, a, v: (c, p, a, v - 1.0), "negative"),
        (lambda c, p, a, v: (c[:0], p[:0], a, v[:0]), "no light/sensor pairs"),
        (lambda c, p, a, v: (c, p, a[:0], v[:, :0]), "non-empty"),
        (lambda c, p, a, v: (c, p, np.r_[a[:3], a[0] + 2 * np.pi], v), "duplicate stage"),
        (lambda c, p, a, v: (c, p, a, v[:, :3]), "expected"),
        (lambda c, p, a, v: (c, p[:5], a, v), "ph_lab"),
        (lambda c, p, a, v: (c[:, :2], p, a, v), r"\(n, 3\)"),
        (lambda c, p, a, v: (c, p, a, np.where(v > 0, np.inf, v)), "infinite"),
        (lambda c, p, a, v: (np.full_like(c, np.deg2rad(85.0)), p, a, v), "horizon"),
    ],
)
def test_bad_input_is_a_clear_error(mutate: object, match: str) -> None:
    cells, ph, alpha, vals = mutate(*_good())  # type: ignore[operator]
    with pytest.raises(ReconstructionError, match=match):
        reconstruct(small_basis(), cells, ph, alpha, vals)


def test_bad_settings_are_clear_errors() -> None:
    cells, ph, alpha, vals = _good()
    b = small_basis()
    with pytest.raises(ReconstructionError, match="solver"):
        reconstruct(b, cells, ph, alpha, vals, solver="magic")  # type: ignore[arg-type]
    with pytest.raises(ReconstructionError, match="eta"):
        reconstruct(b, cells, ph, alpha, vals, eta=-1.0)
    with pytest.raises(ReconstructionError, match="singular"):
        reconstruct(b, cells[:2], ph[:2], alpha, vals[:2], eta=0.0, lam=0.0,
                      method="vf")


def test_basis_on_another_grid_is_refused() -> None:
    b = small_basis()
    other = object.__new__(Basis)  # a basis object from a gonio with another grid
    for name in ("f_med", "mu", "eps", "materials", "provenance", "S"):
        object.__setattr__(other, name, getattr(b, name))
    object.__setattr__(other, "Q", b.Q[:100])
    object.__setattr__(other, "valid", b.valid[:100])
    cells, ph, alpha, vals = _good()
    with pytest.raises(ReconstructionError, match="another grid"):
        reconstruct(other, cells, ph, alpha, vals)


def test_pair_cells_rejects_bad_directions() -> None:
    up = np.array([[0.0, 0.0, 1.0]])
    with pytest.raises(ReconstructionError, match=r"\(n, 3\)"):
        pair_cells(up[:, :2], up[:, :2])
    with pytest.raises(ReconstructionError, match="unit vectors"):
        pair_cells(2 * up, up)
    with pytest.raises(ReconstructionError, match="above the specimen"):
        pair_cells(-up, up)


def test_half_turn_scan_is_recognised_by_its_largest_gap() -> None:
    assert half_turn_scan(np.arange(8) * np.pi / 8)  # 0 .. 157.5 deg
    assert half_turn_scan(np.deg2rad([350.0, 10.0, 100.0]))  # wraps through 0
    assert not half_turn_scan(np.arange(8) * 2 * np.pi / 8)
    assert not half_turn_scan(np.deg2rad([0.0, 180.0]))  # a gap of exactly half a turn
    assert not half_turn_scan(np.array([0.3]))


def test_vf_half_turn_scan_equals_the_full_turn_with_each_reading_repeated() -> None:
    """A specimen that reads the same turned by half a turn: V&F's path on r angles over half
    a turn must give what it gives on the 2 r angles of the full turn, the readings at
    ``alpha + pi`` being copies (PCHIP is local: the same nodes at the same spacing)."""
    b = random_basis(6)  # no ph prior: isotropic, so half-turn periodic
    assert b.half_turn_periodic
    cells, ph = grid_pairs(6, seed=3)
    r = 5
    half = np.arange(r) * np.pi / r
    vals = np.random.default_rng(2).uniform(0.05, 2.0, (6, r, 3))
    got = reconstruct(b, cells, ph, half, vals, method="vf")
    full = np.concatenate([half, half + np.pi])
    want = reconstruct(b, cells, ph, full, np.concatenate([vals, vals], axis=1), method="vf")
    np.testing.assert_allclose(got.table.values, want.table.values, rtol=1e-10, atol=1e-12)


def test_vf_half_turn_scan_of_a_full_turn_prior_is_refused() -> None:
    from tests.unit.brdf.reconstruction.test_reconstruct_joint import _with_prior

    b = _with_prior(random_basis(6), {0: 1.0, 1: 0.3, 2: 0.5})
    assert not b.half_turn_periodic
    cells, ph = grid_pairs(6, seed=3)
    vals = np.random.default_rng(2).uniform(0.05, 2.0, (6, 4, 3))
    with pytest.raises(ReconstructionError, match="only half a turn"):
        reconstruct(b, cells, ph, np.arange(4) * np.pi / 4, vals, method="vf")
    # the joint fit takes the same readings (its prior says what the other half may hold)
    assert np.isfinite(reconstruct(b, cells, ph, np.arange(4) * np.pi / 4, vals).table.values
                       ).any()
