"""Tests of the joint reconstruction (math.md 6): every reading at its own ph."""

from __future__ import annotations

import numpy as np
import pytest

from gonio.brdf.reconstruction.basis import N_HARMONICS, Basis, inverse_remap, row_weight
from gonio.brdf.reconstruction.joint import joint_prior, solve_joint
from gonio.brdf.reconstruction.reconstruct import ReconstructionError, reconstruct
from gonio.brdf.tables import geometry as geo
from tests.unit.brdf.reconstruction.test_reconstruct import grid_pairs, random_basis


def _with_prior(b: Basis, harmonics: dict[int, float]) -> Basis:
    """``b`` with a prior holding the given harmonics (variance per component)."""
    P = np.zeros((N_HARMONICS, b.K, b.K))
    for m, v in harmonics.items():
        P[m] = v * np.eye(b.K)
    return Basis(b.Q, b.S, b.f_med, b.mu, b.valid, b.eps, b.materials, b.provenance, P)


def _truth_table(b: Basis, C: np.ndarray) -> np.ndarray:
    """(72, N_ROWS) values exactly in the span of ``b`` for coefficients C (K, 72)."""
    X = (b.Q @ C).T + b.mu
    with np.errstate(invalid="ignore"):
        out = inverse_remap(X, b.f_med, row_weight(b.eps), b.eps)
    return np.where(b.valid, out, np.nan)


def _read(b: Basis, C_of_ph, cells: np.ndarray, ph: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    """Exact readings (n, r, 1) of the in-span BRDF at each reading's own (off-grid) ph."""
    rows = geo.flat_row(*(np.rint(cells / geo.STEP).astype(int).T))
    phr = ph[:, None] - alpha[None, :]
    X = np.einsum("qk,kqj->qj", b.Q[rows], C_of_ph(phr)) + b.mu[rows][:, None]
    w = row_weight(b.eps)[rows][:, None]
    return inverse_remap(X, b.f_med[rows][:, None], w, b.eps)[..., None]


@pytest.mark.parametrize("rho", ["scan", "scan-bands", None])
def test_an_anisotropic_brdf_in_the_span_is_reproduced_exactly(rho: str | None) -> None:
    """Coefficients varying along ph with harmonics 0, 2 and 4 (the prior's support), read at
    irregular off-grid stage angles: with vanishing noise the joint fit is exact at every
    slice, although no slice was read directly, whatever factors the scan's own prior takes
    (one for all varying harmonics, or one per band)."""
    b = _with_prior(random_basis(5, seed=1), {0: 1.0, 2: 1.0, 4: 0.5})
    rng = np.random.default_rng(3)
    c0, c2, s2, c4, s4 = (0.01 * rng.standard_normal(5) for _ in range(5))

    def coef(phi: np.ndarray) -> np.ndarray:
        return (c0[:, None, None] + c2[:, None, None] * np.cos(2 * phi)[None]
                + s2[:, None, None] * np.sin(2 * phi)[None]
                + c4[:, None, None] * np.cos(4 * phi)[None]
                + s4[:, None, None] * np.sin(4 * phi)[None])

    cells, ph = grid_pairs(12, seed=4)
    alpha = np.deg2rad([3.0, 47.5, 101.0, 170.2, 233.0, 299.9])
    vals = _read(b, coef, cells, ph, alpha)
    assert np.all(vals > 0), "test set-up: the BRDF must be positive"
    rec = reconstruct(b, cells, ph, alpha, vals, channels=("Y",), eta=1e-10, lam=0.0, rho=rho)
    want = coef(geo.PH_GRID[None, :])[:, 0, :]  # (K, 72)
    np.testing.assert_allclose(rec.coefficients[0], want, atol=1e-6)
    truth = _truth_table(b, want)
    got = rec.table.values[0].reshape(geo.N_PH, geo.N_ROWS)[:, b.valid]
    np.testing.assert_allclose(got, np.maximum(truth[:, b.valid], 0.0), rtol=1e-5, atol=1e-9)
    assert rec.settings["method"] == "joint"


def test_an_isotropic_brdf_is_reproduced_by_a_basis_without_prior() -> None:
    """Without a learnt prior the joint fit assumes isotropy (P_0 = I): a ridge over every
    reading, exact for an isotropic in-span BRDF from a few rotations."""
    b = random_basis(5, seed=2)
    assert b.ph_prior is None
    c = 0.1 * np.random.default_rng(6).standard_normal(5)
    cells, ph = grid_pairs(12, seed=8)
    alpha = np.deg2rad([0.0, 50.0, 110.0, 250.0])
    vals = _read(b, lambda phi: np.broadcast_to(c[:, None, None], (5, *phi.shape)), cells, ph,
                 alpha)
    rec = reconstruct(b, cells, ph, alpha, vals, channels=("Y",), eta=1e-10)
    np.testing.assert_allclose(rec.coefficients[0], c[:, None] * np.ones(72), atol=1e-7)
    assert rec.cv_sample_error < 1e-6 and rec.cv_log_error < 1e-6


def test_joint_fit_equals_ridge_over_all_readings_when_isotropic() -> None:
    """With P_0 = I only, the posterior mean is (Q^T Q + eta I)^-1 Q^T y over all readings."""
    rng = np.random.default_rng(0)
    n, r, K = 7, 5, 4
    Qt = rng.standard_normal((n, K))
    Y = rng.standard_normal((n, r, 2))
    P = np.zeros((N_HARMONICS, K, K))
    P[0] = np.eye(K)
    eta = 3.0
    jf = solve_joint(Y, Qt, rng.uniform(0, 2 * np.pi, (n, r)), P, eta)
    A = np.repeat(Qt, r, axis=0)
    want = np.linalg.solve(A.T @ A + eta * np.eye(K), A.T @ Y.reshape(n * r, 2))
    np.testing.assert_allclose(jf.coef, np.broadcast_to(want[:, None, :], jf.coef.shape),
                               atol=1e-10)


def test_leave_one_pair_out_equals_refits() -> None:
    rng = np.random.default_rng(1)
    n, r, K = 6, 4, 3
    Qt = rng.standard_normal((n, K))
    Y = rng.standard_normal((n, r, 1))
    phr = rng.uniform(0, 2 * np.pi, (n, r))
    P = np.zeros((N_HARMONICS, K, K))
    P[0], P[2], P[4] = np.eye(K), 0.5 * np.eye(K), 0.2 * np.eye(K)
    eta = 0.7
    jf = solve_joint(Y, Qt, phr, P, eta)
    for q in range(n):
        keep = np.arange(n) != q
        sub = solve_joint(Y[keep], Qt[keep], phr[keep], P, eta, ph_out=phr[q])
        pred = np.einsum("k,kjc->jc", Qt[q], sub.coef)
        np.testing.assert_allclose(jf.loo[q], pred, atol=1e-10)


def test_specular_condition_damps_variation_at_th0() -> None:
    """Eq. 5's th = 0 term: with lam > 0 the prior's varying part shrinks along Qs."""
    b = _with_prior(random_basis(4, seed=5), {0: 1.0, 2: 1.0})
    Qs = b.Q[np.flatnonzero(b.valid)[np.flatnonzero(b.valid) < geo.N_TD * geo.N_PD]]
    free = np.trace(Qs @ joint_prior(b, 0.0)[2] @ Qs.T)
    damped = np.trace(Qs @ joint_prior(b, 1.0)[2] @ Qs.T)
    assert damped < 0.1 * free
    np.testing.assert_array_equal(joint_prior(b, 1.0)[0], joint_prior(b, 0.0)[0])


def test_joint_fit_rejects_zero_noise_and_unknown_methods() -> None:
    b = random_basis(4)
    cells, ph = grid_pairs(5)
    alpha = np.deg2rad([0.0, 90.0])
    vals = np.ones((5, 2, 1))
    with pytest.raises(ReconstructionError, match="eta > 0"):
        reconstruct(b, cells, ph, alpha, vals, channels=("Y",), eta=0.0)
    with pytest.raises(ReconstructionError, match="method"):
        reconstruct(b, cells, ph, alpha, vals, channels=("Y",), method="pchip")  # type: ignore[arg-type]


def test_leave_one_angle_out_equals_refits() -> None:
    rng = np.random.default_rng(2)
    n, r, K = 5, 6, 3
    Qt = rng.standard_normal((n, K))
    Y = rng.standard_normal((n, r, 1))
    alpha = np.sort(rng.uniform(0, 2 * np.pi, r))
    ph = rng.uniform(0, 2 * np.pi, n)
    phr = ph[:, None] - alpha[None, :]
    P = np.zeros((N_HARMONICS, K, K))
    P[0], P[2] = np.eye(K), 0.8 * np.eye(K)
    jf = solve_joint(Y, Qt, phr, P, 0.5)
    for j in range(r):
        keep = np.arange(r) != j
        sub = solve_joint(Y[:, keep], Qt, phr[:, keep], P, 0.5, ph_out=phr[:, j])
        pred = np.einsum("qk,kq->q", Qt, sub.coef[:, :, 0])
        np.testing.assert_allclose(jf.loo_angle[:, j, 0], pred, atol=1e-10)


def test_refine_angles_plans_midpoints_around_bad_angles_worst_first() -> None:
    from gonio.brdf.reconstruction.reconstruct import refine_angles

    angles = [0.0, 90.0, 180.0, 270.0]
    errs = [0.001, 0.05, 0.002, 0.03]
    assert refine_angles(angles, errs, 0.01, 1.0, None) == [45.0, 135.0, 225.0, 315.0]
    # Budget: the midpoints of the worst angle (90 deg) come first.
    assert refine_angles(angles, errs, 0.01, 1.0, 2) == [45.0, 135.0]
    assert refine_angles(angles, errs, 0.1, 1.0, None) == []
    # A gap finer than twice the minimum step is not split; the wide gap round 360 is.
    assert refine_angles([0.0, 1.5], [0.5, 0.5], 0.01, 1.0, None) == [180.75]


def test_the_leave_one_pair_out_under_prediction_counts_only_readings_above_their_prediction(
        ) -> None:
    """``cv_log_under``: RMS over every reading of ``max(0, ln(1 + y c) - ln(1 + f_loo c))``.

    Two readings at ``cos ti`` = 1: one ``e - 1`` against a prediction of 0 (1 log unit
    above), one 0 against a prediction of 3 (below: counts 0); RMS over the two readings is
    ``sqrt(1 / 2)``. The exact in-span fit above has none."""
    from gonio.brdf.reconstruction.reconstruct import _log_under

    pred = np.array([[[0.0]], [[3.0]]])
    measured = np.array([[[np.e - 1.0]], [[0.0]]])
    assert _log_under(pred, measured, np.ones(2)) == pytest.approx(np.sqrt(0.5))
    assert _log_under(measured, measured, np.ones(2)) == 0.0
    b = random_basis(5, seed=2)
    c = 0.1 * np.random.default_rng(6).standard_normal(5)
    cells, ph = grid_pairs(12, seed=8)
    alpha = np.deg2rad([0.0, 50.0, 110.0, 250.0])
    vals = _read(b, lambda phi: np.broadcast_to(c[:, None, None], (5, *phi.shape)), cells, ph,
                 alpha)
    rec = reconstruct(b, cells, ph, alpha, vals, channels=("Y",), eta=1e-10)
    assert 0.0 <= rec.cv_log_under <= rec.cv_log_error + 1e-12 and rec.cv_log_under < 1e-6
