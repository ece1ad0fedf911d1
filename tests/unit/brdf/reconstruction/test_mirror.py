"""Tests of the joint fit's mirror symmetry chosen per scan (``symmetry="scan"``)."""

from __future__ import annotations

import numpy as np
import pytest

from gonio.brdf.models import analytic as bm
from gonio.brdf.reconstruction.basis import Basis, inverse_remap, row_weight
from gonio.brdf.reconstruction.mirror import MirrorModel, mirror_cells
from gonio.brdf.reconstruction.reconstruct import ReconstructionError, joint_prior, reconstruct
from gonio.brdf.tables import geometry as geo
from tests.unit.brdf.reconstruction.test_reconstruct import grid_pairs, random_basis
from tests.unit.brdf.reconstruction.test_reconstruct_joint import _with_prior

HARMONICS = {0: 1.0, 2: 1.0, 4: 0.5}


def _mirror_rows() -> np.ndarray:
    """(N_ROWS,) flat row of each row's mirror cell (th, td, pi - pd)."""
    i = np.arange(geo.N_ROWS)
    th, td, pd = np.unravel_index(i, geo.SLICE_SHAPE)
    return np.ravel_multi_index((th, td, (geo.N_PD - pd) % geo.N_PD), geo.SLICE_SHAPE)


def _symmetric_basis(k: int) -> Basis:
    """A random basis whose rows, f_med and mu repeat at the mirror cells, with a prior on
    harmonics 0, 2 and 4: a material with coefficients even about an axis is then exactly
    mirror-symmetric about it."""
    b = random_basis(k, seed=1)
    src = np.minimum(np.arange(geo.N_ROWS), _mirror_rows())  # copy the pd <= 90 deg half
    out = Basis(b.Q[src], b.S, b.f_med[src], b.mu[src], b.valid, b.eps)
    return _with_prior(out, HARMONICS)


def test_mirror_cells_reflect_pd_about_a_quarter_turn() -> None:
    """pd -> pi - pd (mod pi); th and td unchanged; and the mirror of a direction pair about
    an axis ph0 is the pair at (th, 2 ph0 - ph, td, pi - pd) (an anisotropic GGX lobe turned
    to ph0 gives the same value at both)."""
    cells = np.deg2rad([[10.0, 20.0, 0.0], [30.0, 40.0, 35.0], [5.0, 60.0, 175.0]])
    np.testing.assert_allclose(np.rad2deg(mirror_cells(cells)),
                               [[10.0, 20.0, 0.0], [30.0, 40.0, 145.0], [5.0, 60.0, 5.0]],
                               atol=1e-12)
    model = bm.Rotated(bm.GGX(0.08, 0.4, bm.DielectricFresnel(1.5)), 0.7)
    rng = np.random.default_rng(0)
    th, td = rng.uniform(0.0, 1.2, (2, 50))
    ph, pd = rng.uniform(0.0, 2 * np.pi, 50), rng.uniform(0.0, np.pi, 50)
    m = mirror_cells(np.stack([th, td, pd], axis=1))
    a = model.eval(*geo.half_diff_to_directions(th, ph, td, pd))
    b = model.eval(*geo.half_diff_to_directions(m[:, 0], 2 * 0.7 - ph, m[:, 1], m[:, 2]))
    np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-12)


def _readings(b: Basis, coef_of_ph, cells: np.ndarray, ph: np.ndarray,
              alpha: np.ndarray) -> np.ndarray:
    rows = geo.flat_row(*(np.rint(cells / geo.STEP).astype(int).T))
    phr = ph[:, None] - alpha[None, :]
    X = np.einsum("qk,kqj->qj", b.Q[rows], coef_of_ph(phr)) + b.mu[rows][:, None]
    w = row_weight(b.eps)[rows][:, None]
    return inverse_remap(X, b.f_med[rows][:, None], w, b.eps)[..., None]


def test_a_symmetric_brdf_is_found_and_reproduced_where_the_plain_fit_cannot() -> None:
    """Coefficients even about the axis 35 deg (harmonics 0, 2, 4), 6 pairs x 3 angles: each
    pair sees a trigonometric polynomial of degree 4 in ph (5 numbers) at 3 azimuths, too
    few for the plain fit; even about an axis it has 3 numbers, so with the symmetry the 18
    readings determine it. The scan finds the axis (or the one a quarter turn away, the same
    for even harmonics) and the fit is exact at every slice; without the symmetry it is
    not."""
    b = _symmetric_basis(5)
    rng = np.random.default_rng(3)
    c0, c2, c4 = (0.02 * rng.standard_normal(5) for _ in range(3))
    axis = np.deg2rad(35.0)

    def coef(phi: np.ndarray) -> np.ndarray:
        return (c0[:, None, None] + c2[:, None, None] * np.cos(2 * (phi - axis))[None]
                + c4[:, None, None] * np.cos(4 * (phi - axis))[None])

    cells, ph = grid_pairs(6, seed=5)
    alpha = np.deg2rad([0.0, 70.0, 150.0])
    vals = _readings(b, coef, cells, ph, alpha)
    want = coef(geo.PH_GRID[None, :])[:, 0, :]
    sym = reconstruct(b, cells, ph, alpha, vals, channels=("Y",), eta=1e-9, lam=0.0,
                      rho=None, symmetry="scan")
    found = sym.settings["mirror_axis_deg"]
    assert found is not None and min(abs(found - 35.0), abs(found - 125.0)) < 1e-6
    np.testing.assert_allclose(sym.coefficients[0], want, atol=1e-5)
    plain = reconstruct(b, cells, ph, alpha, vals, channels=("Y",), eta=1e-9, lam=0.0,
                        rho=None)
    assert plain.settings.get("mirror_axis_deg") is None
    assert np.abs(plain.coefficients[0] - want).max() > 100 * np.abs(
        sym.coefficients[0] - want).max()


def test_readings_without_symmetry_keep_the_plain_fit() -> None:
    """Coefficients with cos and sin parts of harmonics 2 and 4 at unrelated phases (no axis
    makes them even), read densely: the marginal likelihood rejects every symmetry and the
    fit is the plain one."""
    b = _symmetric_basis(5)
    rng = np.random.default_rng(11)
    c0, c2, s2, c4, s4 = (0.02 * rng.standard_normal(5) for _ in range(5))

    def coef(phi: np.ndarray) -> np.ndarray:
        return (c0[:, None, None] + c2[:, None, None] * np.cos(2 * phi)[None]
                + s2[:, None, None] * np.sin(2 * phi)[None]
                + c4[:, None, None] * np.cos(4 * phi)[None]
                + s4[:, None, None] * np.sin(4 * phi)[None])

    cells, ph = grid_pairs(8, seed=6)
    alpha = np.deg2rad(np.arange(0.0, 360.0, 30.0))
    vals = _readings(b, coef, cells, ph, alpha)
    rec = reconstruct(b, cells, ph, alpha, vals, channels=("Y",), eta=1e-6, lam=0.0,
                      rho=None, symmetry="scan")
    assert rec.settings["mirror_axis_deg"] is None
    plain = reconstruct(b, cells, ph, alpha, vals, channels=("Y",), eta=1e-6, lam=0.0,
                        rho=None)
    np.testing.assert_array_equal(rec.coefficients, plain.coefficients)


def test_the_symmetric_likelihood_is_the_conditional_gaussian_density() -> None:
    """MirrorModel.log_marginal(axis, slack) + const is ln p(y | x' - x = delta) at the
    maximising scale, from the augmented covariance written out element by element and
    scipy's multivariate normal on the conditional mean and covariance."""
    from scipy.stats import multivariate_normal

    b = _with_prior(random_basis(4, seed=2), {0: 1.0, 2: 0.7, 4: 0.3})
    cells, ph = grid_pairs(3, seed=7)
    alpha = np.deg2rad([0.0, 100.0, 230.0])
    rng = np.random.default_rng(4)
    Y = rng.normal(0.0, 0.3, (3, 3, 2))
    Ym = Y + rng.normal(0.0, 0.05, (3, 1, 1))
    th, td, pd = cells.T
    rows, w = b.neighbours(th, td, pd)
    Qt = np.einsum("nj,njk->nk", w, b.Q[rows])
    mth, mtd, mpd = mirror_cells(cells).T
    mrows, mw = b.neighbours(mth, mtd, mpd)
    Qm = np.einsum("nj,njk->nk", mw, b.Q[mrows])
    phr = ph[:, None] - alpha[None, :]
    P = joint_prior(b, 0.0)
    eta, slack, axis = 0.5, 2.0, np.deg2rad(23.0)
    model = MirrorModel(Y, Ym, Qt, Qm, phr, P, eta)

    rows_all = np.concatenate([np.repeat(Qt, 3, axis=0), np.repeat(Qm, 3, axis=0)])
    ph_all = np.concatenate([phr.ravel(), (2 * axis - phr).ravel()])
    N = 9
    U = np.empty((2 * N, 2 * N))
    for a in range(2 * N):
        for c in range(2 * N):
            Pd = sum(P[m] * np.cos(m * (ph_all[a] - ph_all[c])) for m in range(P.shape[0]))
            U[a, c] = rows_all[a] @ Pd @ rows_all[c]
    T = np.block([[np.eye(N), np.zeros((N, N))], [-np.eye(N), np.eye(N)]])
    cov = T @ U @ T.T + np.diag(np.r_[np.full(N, eta), np.full(N, slack * eta)])
    y, d = Y.reshape(N, 2), (Ym - Y).reshape(N, 2)
    gain = cov[:N, N:] @ np.linalg.inv(cov[N:, N:])
    mean, S = gain @ d, cov[:N, :N] - gain @ cov[N:, :N]
    r = y - mean
    s2 = float(np.sum(r * np.linalg.solve(S, r))) / (N * 2)
    want = sum(multivariate_normal(mean[:, c], s2 * S).logpdf(y[:, c]) for c in range(2))
    const = -0.5 * N * 2 * (1.0 + np.log(2 * np.pi))
    assert model.log_marginal(axis, slack) + const == pytest.approx(want, rel=1e-8)
    G = U[:N, :N] + eta * np.eye(N)
    s2p = float(np.sum(y * np.linalg.solve(G, y))) / (N * 2)
    plain = sum(multivariate_normal(np.zeros(N), s2p * G).logpdf(y[:, c]) for c in range(2))
    assert model.log_marginal(None) + const == pytest.approx(plain, rel=1e-8)


def test_symmetry_must_be_scan_or_none() -> None:
    b = _with_prior(random_basis(4, seed=2), HARMONICS)
    cells, ph = grid_pairs(3, seed=7)
    alpha = np.deg2rad([0.0, 100.0, 230.0])
    vals = np.ones((3, 3, 1))
    with pytest.raises(ReconstructionError, match="symmetry"):
        reconstruct(b, cells, ph, alpha, vals, channels=("Y",), symmetry="mirror")  # type: ignore[arg-type]
