"""Tests of the expected-error design (gonio.brdf.design.posterior)."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from gonio.brdf.design.constraints import RigConstraints, feasible_mask
from gonio.brdf.design.errors import DesignError
from gonio.brdf.design.posterior import (
    PriorModel,
    _posterior,
    cell_gram,
    expected_error,
    folded_onto,
    greedy_rows,
    metric_gram,
    posterior_design,
    prior_model,
)
from gonio.brdf.reconstruction.basis import N_HARMONICS, Basis, inverse_remap, row_weight
from gonio.brdf.reconstruction.reconstruct import solve_joint
from gonio.brdf.tables import geometry as geo
from tests.unit.brdf.reconstruction.test_reconstruct import random_basis
from tests.unit.brdf.reconstruction.test_reconstruct_joint import _with_prior


def _spd(k: int, rng: np.random.Generator) -> np.ndarray:
    A = rng.standard_normal((k, k))
    return A @ A.T / k + 0.1 * np.eye(k)


def test_posterior_equals_the_information_form() -> None:
    """``P - P Q^T (Q P Q^T + s I)^-1 Q P`` is ``(P^-1 + Q^T Q / s)^-1`` (Woodbury)."""
    rng = np.random.default_rng(0)
    P, Q, s = _spd(6, rng), rng.standard_normal((4, 6)), 0.3
    want = np.linalg.inv(np.linalg.inv(P) + Q.T @ Q / s)
    np.testing.assert_allclose(_posterior(P, Q, s), want, rtol=1e-9, atol=1e-12)


def test_expected_error_matches_monte_carlo_of_the_joint_fit() -> None:
    """Draw coefficient functions from the prior (harmonics 0 and 2), read them at uniform
    stage angles with noise ``eta``, fit with ``solve_joint``: the mean W-weighted squared
    error over the 72 slices is the model's ``sum_m tr(W Sigma_m)``."""
    rng = np.random.default_rng(1)
    k, n, r, eta, draws = 5, 3, 8, 0.5, 4000
    P0, P2 = _spd(k, rng), 0.5 * _spd(k, rng)
    P = np.zeros((N_HARMONICS, k, k))
    P[0], P[2] = P0, P2
    W = _spd(k, rng)
    Qt = rng.standard_normal((n, k))
    ph_lab = rng.uniform(0, 2 * np.pi, n)
    alpha = np.arange(r) * 2 * np.pi / r
    phr = ph_lab[:, None] - alpha[None, :]  # (n, r)
    L0, L2 = np.linalg.cholesky(P0), np.linalg.cholesky(P2)
    a0 = L0 @ rng.standard_normal((k, draws))
    a2, b2 = L2 @ rng.standard_normal((k, draws)), L2 @ rng.standard_normal((k, draws))

    def c_at(ph: np.ndarray) -> np.ndarray:  # (..., k, draws)
        return (a0 + np.cos(2 * ph)[..., None, None] * a2
                + np.sin(2 * ph)[..., None, None] * b2)

    Y = np.einsum("qk,qjkd->qjd", Qt, c_at(phr)) + np.sqrt(eta) * rng.standard_normal(
        (n, r, draws))
    fit = solve_joint(Y, Qt, phr, P, eta)  # coef (k, 72, draws)
    err = fit.coef - np.moveaxis(c_at(geo.PH_GRID), 0, 1)  # (k, 72, draws)
    mc = float(np.mean(np.einsum("ksd,kl,lsd->sd", err, W, err)))
    model = PriorModel(np.stack([P0, P2]), np.array([0, 2]),
                       np.array([eta / r, 2 * eta / r]), W)
    assert expected_error(model, Qt) == pytest.approx(mc, rel=0.05)
    # and the readings matter: without them the error is the prior's
    assert expected_error(model, np.zeros((1, k))) > 1.5 * mc


def test_greedy_first_pick_is_the_best_single_pair_and_each_step_lowers_the_error() -> None:
    rng = np.random.default_rng(2)
    k = 4
    model = PriorModel(np.stack([_spd(k, rng), _spd(k, rng)]), np.array([0, 2]),
                       np.array([0.2, 0.4]), _spd(k, rng))
    Q = rng.standard_normal((30, k))
    cand = np.arange(3, 30, 2)
    rows = greedy_rows(model, Q, cand, 4)
    single = [expected_error(model, Q[[c]]) for c in cand]
    assert rows[0] == cand[int(np.argmin(single))]
    errs = [expected_error(model, Q[rows[:i]]) for i in range(1, 5)]
    assert all(b < a for a, b in itertools.pairwise(errs))
    assert len(set(rows.tolist())) == 4 and set(rows.tolist()) <= set(cand.tolist())


def test_metric_gram_is_the_weighted_sum_over_valid_rows() -> None:
    """W from the slope of ln(1 + f cos ti) in the remapped value, taken by finite differences
    through the basis' own inverse remap at every valid row."""
    b = random_basis(3)
    rows = np.flatnonzero(b.valid)
    ci, _ = geo.cell_cosines(*geo.grid_angles())
    c_i = ci.ravel()[rows]
    w = row_weight(b.eps)[rows]
    x0 = np.zeros(rows.size)  # remapped value of the median itself
    h = 1e-6
    f0 = inverse_remap(x0, b.f_med[rows], w, b.eps)
    f1 = inverse_remap(x0 + h, b.f_med[rows], w, b.eps)
    s = (np.log1p(f1 * c_i) - np.log1p(f0 * c_i)) / h
    wv = geo.volume_weight().ravel()[rows]
    want = np.einsum("r,rk,rl->kl", wv * s**2, b.Q[rows], b.Q[rows])
    np.testing.assert_allclose(metric_gram(b, "median"), want, rtol=1e-4)
    assert np.all(np.linalg.eigvalsh(metric_gram(b, "median")) > 0)
    # a basis that does not say how many columns it summarises gets the median slope
    np.testing.assert_array_equal(metric_gram(b), metric_gram(b, "median"))


def test_metric_gram_spread_matches_a_monte_carlo_over_the_basis_materials() -> None:
    """``slope="spread"``: draw coefficient vectors with the training covariance ``sum_m P_m /
    n_columns``, turn them into values through the basis' own inverse remap, take the metric's
    slope by finite differences at each drawn value, and average ``s^2`` per row."""
    base = _with_prior(random_basis(4, seed=5), {0: 0.7, 2: 0.3})
    b = Basis(base.Q, base.S, base.f_med, base.mu, base.valid, base.eps, base.materials,
              {"n_columns": 40.0}, base.ph_prior)
    rows = np.flatnonzero(b.valid)
    ci, _ = geo.cell_cosines(*geo.grid_angles())
    c_i = ci.ravel()[rows]
    w = row_weight(b.eps)[rows]
    rng = np.random.default_rng(11)
    draws, h = 3000, 1e-6
    C = rng.standard_normal((b.K, draws)) / np.sqrt(40.0)  # sum_m P_m = I here
    s2 = np.zeros(rows.size)
    for lo in range(0, rows.size, 1000):
        r = rows[lo : lo + 1000]
        x = b.mu[r, None] + b.Q[r] @ C
        args = (b.f_med[r, None], w[lo : lo + 1000, None], b.eps)
        f0 = np.maximum(inverse_remap(x, *args), 0.0)
        f1 = np.maximum(inverse_remap(x + h, *args), 0.0)
        ci_r = c_i[lo : lo + 1000, None]
        s2[lo : lo + 1000] = np.mean(((np.log1p(f1 * ci_r) - np.log1p(f0 * ci_r)) / h) ** 2, 1)
    wv = geo.volume_weight().ravel()[rows]
    want = np.einsum("r,rk,rl->kl", wv * s2, b.Q[rows], b.Q[rows])
    got = metric_gram(b, "spread")
    np.testing.assert_allclose(got, want, rtol=0.03, atol=0.03 * np.abs(want).max())
    # and it is not the median slope: the spread of values weighs the rows differently
    assert np.abs(metric_gram(b, "median") - want).max() > 0.1 * np.abs(want).max()
    with pytest.raises(DesignError, match="slope must be"):
        metric_gram(b, "mean")  # type: ignore[arg-type]


def test_cell_gram_weighs_each_cell_by_the_map_and_the_metric_slope() -> None:
    """One cell weighted: ``W = c s^2 q q^T`` with ``s`` by finite differences through the
    basis' inverse remap (as for metric_gram); the volume weight as map gives metric_gram."""
    b = random_basis(3)
    rows = np.flatnonzero(b.valid)
    r = int(rows[1234])
    ci, _ = geo.cell_cosines(*geo.grid_angles())
    w = row_weight(b.eps)[r]
    h = 1e-6
    f0 = inverse_remap(np.zeros(1), b.f_med[[r]], w, b.eps)
    f1 = inverse_remap(np.full(1, h), b.f_med[[r]], w, b.eps)
    s = float((np.log1p(f1 * ci.ravel()[r]) - np.log1p(f0 * ci.ravel()[r]))[0] / h)
    c = np.zeros(geo.N_ROWS)
    c[r] = 2.5
    np.testing.assert_allclose(cell_gram(b, c.reshape(geo.SLICE_SHAPE)),
                               2.5 * s**2 * np.outer(b.Q[r], b.Q[r]), rtol=1e-4, atol=1e-12)
    # an invalid cell's weight is left out
    c[np.flatnonzero(~b.valid)[0]] = 100.0
    np.testing.assert_allclose(cell_gram(b, c), 2.5 * s**2 * np.outer(b.Q[r], b.Q[r]),
                               rtol=1e-4, atol=1e-12)
    np.testing.assert_allclose(cell_gram(b, geo.volume_weight()), metric_gram(b), rtol=1e-12)


@pytest.mark.parametrize(("weight", "match"), [
    (np.ones(10), "one value per grid cell"),
    (-np.ones(geo.SLICE_SHAPE), "finite and >= 0"),
    (np.full(geo.SLICE_SHAPE, np.nan), "finite and >= 0"),
    (np.where(geo.valid_mask(), 0.0, 1.0), "no weight on any valid cell"),
])
def test_cell_gram_rejects_bad_maps(weight: np.ndarray, match: str) -> None:
    with pytest.raises(DesignError, match=match):
        cell_gram(random_basis(3), weight)


def test_cell_mix_chooses_by_the_mixed_expected_error() -> None:
    """The first pair of a design with ``cell_mix = a`` is the best single pair under
    ``(1 - a) E_W + a ratio E_Wc``, ``ratio = sum(W P) / sum(Wc P)`` over the summed prior,
    evaluated pair by pair with expected_error; the reported expected log_rmse stays the
    table's. Mixing in the table's own weights (the volume) changes nothing."""
    from dataclasses import replace

    from gonio.brdf.design.posterior import design_expected_log_rmse

    b = _with_prior(random_basis(6), {0: 1.0, 2: 0.5})
    cons = RigConstraints(min_device_distance_deg=0.0)
    model = prior_model(b, 8)
    cand = np.flatnonzero(feasible_mask(cons, b.valid).ravel())
    plain_err = np.array([expected_error(model, b.Q[[c]]) for c in cand])
    # A map on one cell whose row the prior knows least, other than the table's first choice:
    # a pair read there teaches most about that cell.
    spread = np.einsum("nk,kl,nl->n", b.Q[cand], model.P[0], b.Q[cand])
    spread[int(np.argmin(plain_err))] = -np.inf
    cmap = np.zeros(geo.N_ROWS)
    cmap[cand[int(np.argmax(spread))]] = 1.0
    Wc = cell_gram(b, cmap)
    Ps = model.P.sum(axis=0)
    ratio = np.sum(model.W * Ps) / np.sum(Wc * Ps)
    for a in (0.7, 1.0):
        mixed = np.array([(1 - a) * expected_error(model, b.Q[[c]])
                          + a * ratio * expected_error(replace(model, W=Wc), b.Q[[c]])
                          for c in cand])
        d = posterior_design(b, 3, cons, cell_weight=cmap.reshape(geo.SLICE_SHAPE),
                             cell_mix=a)
        first = np.ravel_multi_index(tuple(np.rint(d.cells[0] / geo.STEP).astype(int)),
                                     geo.SLICE_SHAPE)
        assert first == cand[int(np.argmin(mixed))]
        q = b.rows_at(d.cells[:, 0], d.cells[:, 1], d.cells[:, 2])
        assert d.expected_log_rmse == pytest.approx(design_expected_log_rmse(model, q))
    assert first != cand[int(np.argmin(plain_err))]  # the map moved the choice
    plain = posterior_design(b, 3, cons)
    same = posterior_design(b, 3, cons, cell_weight=geo.volume_weight(), cell_mix=1.0)
    np.testing.assert_allclose(same.cells, plain.cells)


@pytest.mark.parametrize(("kwargs", "match"), [
    ({"cell_mix": 0.5}, "needs a cell_weight"),
    ({"cell_mix": -0.1, "cell_weight": np.ones(geo.SLICE_SHAPE)}, r"cell_mix must be in \[0, 1\]"),
    ({"cell_mix": 1.5, "cell_weight": np.ones(geo.SLICE_SHAPE)}, r"cell_mix must be in \[0, 1\]"),
])
def test_cell_mix_rejects_bad_requests(kwargs: dict, match: str) -> None:
    with pytest.raises(DesignError, match=match):
        posterior_design(random_basis(4), 3, RigConstraints(), **kwargs)


def test_cell_mix_with_a_colour_design_is_refused() -> None:
    """The mix would scale against a metric already holding the colour term."""
    from gonio.sampling_design import colour_targets

    with pytest.raises(DesignError, match="colour design cannot also mix in a cell weighting"):
        posterior_design(random_basis(4), 6, RigConstraints(), colour=colour_targets("MA98"),
                         cell_weight=np.ones(geo.SLICE_SHAPE), cell_mix=0.5)


def test_posterior_design_gives_distinct_feasible_mountable_pairs() -> None:
    b = _with_prior(random_basis(6), {0: 1.0, 2: 0.5})
    cons = RigConstraints()
    d = posterior_design(b, 5, cons)
    assert d.name == "optimized" and d.objective == "posterior" and d.cells.shape == (5, 3)
    # Its own statistics, none of the condition-number search's.
    assert d.search is None and d.greedy is not None and d.fallback is None
    n_feasible = int(feasible_mask(cons, b.valid).sum())
    assert d.greedy.candidates == n_feasible and d.greedy.evaluations == 5 * n_feasible
    assert d.greedy.mount_checks >= 5 and d.greedy.first == 0
    assert d.rotations == 8
    idx = np.rint(d.cells / geo.STEP).astype(int)
    assert len({tuple(i) for i in idx}) == 5
    assert feasible_mask(cons, b.valid)[tuple(idx.T)].all()
    assert d.min_distance_deg >= cons.min_device_distance_deg - 1e-6
    assert np.isfinite(d.kappa)
    # r = 1 resolves only the mean: the prior keeps harmonic 0 alone
    assert prior_model(b, 1).harmonics.tolist() == [0]
    assert prior_model(b, 8).harmonics.tolist() == [0, 2]


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [({"n": 0}, "at least 1"), ({"n": 10**6}, "feasible cells"),
     ({"n": 3, "rotations": 0}, "stage angle"), ({"n": 3, "eta": 0.0}, "eta must be")],
)
def test_posterior_design_rejects_bad_requests(kwargs: dict, match: str) -> None:
    b = random_basis(4)
    with pytest.raises(DesignError, match=match):
        posterior_design(b, constraints=RigConstraints(), **kwargs)


def test_design_pairs_objective_posterior_is_the_expected_error_design() -> None:
    from gonio.brdf.design.pairs import design_pairs

    b = _with_prior(random_basis(6), {0: 1.0, 2: 0.5})
    via = design_pairs(b, 4, RigConstraints(), objective="posterior")
    direct = posterior_design(b, 4, RigConstraints())
    np.testing.assert_array_equal(via.cells, direct.cells)
    assert via.objective == "posterior" and via.expected_log_rmse == direct.expected_log_rmse
    with pytest.raises(DesignError, match="objective must be one of kappa, posterior"):
        design_pairs(b, 4, RigConstraints(), objective="nope")  # type: ignore[arg-type]


def test_design_pairs_passes_a_cell_weighting_to_the_expected_error_design_only() -> None:
    from gonio.brdf.design.pairs import design_pairs

    b = _with_prior(random_basis(6), {0: 1.0, 2: 0.5})
    cmap = np.where(geo.grid_angles()[0] > np.deg2rad(70), 1.0, 0.0)
    via = design_pairs(b, 4, RigConstraints(), cell_weight=cmap, cell_mix=0.8)
    direct = posterior_design(b, 4, RigConstraints(), cell_weight=cmap, cell_mix=0.8)
    np.testing.assert_array_equal(via.cells, direct.cells)
    with pytest.raises(DesignError, match="expected-error design only"):
        design_pairs(b, 4, RigConstraints(), objective="kappa", cell_weight=cmap, cell_mix=0.8)


def test_design_pairs_objective_posterior_needs_a_basis() -> None:
    from gonio.brdf.design.pairs import design_pairs

    class RowsOnly:
        def __init__(self, b: object) -> None:
            self.Q, self.valid, self.rows_at = b.Q, b.valid, b.rows_at  # type: ignore[attr-defined]

    with pytest.raises(DesignError, match="needs a gonio Basis"):
        design_pairs(RowsOnly(random_basis(4)), 3, RigConstraints(), objective="posterior")


def test_expected_log_rmse_is_the_root_of_the_scaled_error_over_the_volume() -> None:
    """In log_rmse units: the prior of one material is ``P / n_columns`` and log_rmse divides
    by the volume weights of the valid cells (``tables.metrics.log_rmse``)."""
    from gonio.brdf.design.posterior import design_expected_log_rmse

    b = _with_prior(random_basis(5), {0: 1.0, 2: 0.5})
    trained = type(b)(b.Q, b.S, b.f_med, b.mu, b.valid, b.eps, b.materials,
                      {"n_columns": 400}, b.ph_prior)
    rows = b.Q[[100, 2000, 3000]]
    wv = float(np.sum(geo.volume_weight()[geo.valid_mask()]))
    raw = expected_error(prior_model(b, 8), rows)
    assert design_expected_log_rmse(prior_model(b, 8), rows) == pytest.approx(np.sqrt(raw / wv))
    # the same weights for both (a trained basis would otherwise get the spread slope)
    assert design_expected_log_rmse(prior_model(trained, 8, slope="median"), rows) == pytest.approx(
        np.sqrt(raw / 400 / wv))


def test_a_seed_starts_the_greedy_from_a_lesser_first_pair() -> None:
    """Seed k takes the k-th best single pair first (several seeds: different candidates)."""
    b = _with_prior(random_basis(6), {0: 1.0, 2: 0.5})
    cons = RigConstraints(min_device_distance_deg=0.0)
    model = prior_model(b, 8)
    cand = np.flatnonzero(feasible_mask(cons, b.valid).ravel())
    single = np.array([expected_error(model, b.Q[[c]]) for c in cand])
    ranked = cand[np.argsort(single)]
    for seed in (0, 2):
        d = posterior_design(b, 3, cons, seed=seed)
        first = np.ravel_multi_index(tuple(np.rint(d.cells[0] / geo.STEP).astype(int)),
                                     geo.SLICE_SHAPE)
        assert first == ranked[seed] and d.greedy is not None and d.greedy.first == seed
        assert d.greedy.mount_checks == 0  # nothing can collide without a distance limit
    # Any seed works: it wraps around the 64 best first pairs.
    d = posterior_design(b, 3, cons, seed=64 * 1000 + 2)
    assert d.greedy is not None and d.greedy.first == 2
    with pytest.raises(DesignError, match="seed must be at least 0"):
        posterior_design(b, 3, cons, seed=-1)


def _harmonic_error(err: np.ndarray, keep: list[int]) -> np.ndarray:
    """(k, 72, draws) error along ph -> the part in harmonics ``keep`` (inverse DFT)."""
    F = np.fft.rfft(err, axis=1)
    mask = np.zeros(F.shape[1], dtype=bool)
    mask[keep] = True
    return np.fft.irfft(np.where(mask[None, :, None], F, 0.0), n=err.shape[1], axis=1)


def _fit_errors(P: np.ndarray, harmonics: tuple[int, ...], Qt: np.ndarray, phr: np.ndarray,
                eta: float, draws: int, rng: np.random.Generator) -> np.ndarray:
    """(k, 72, draws) errors of ``solve_joint`` on functions drawn from the prior ``P``
    (harmonics ``harmonics``, 0 first), read by pairs with rows ``Qt`` at ``phr`` (n, r) with
    noise variance ``eta``."""
    k = Qt.shape[1]
    L = {m: np.linalg.cholesky(P[m]) for m in harmonics}
    a = {m: L[m] @ rng.standard_normal((k, draws)) for m in harmonics}
    b = {m: L[m] @ rng.standard_normal((k, draws)) for m in harmonics if m > 0}

    def c_at(ph: np.ndarray) -> np.ndarray:  # (..., k, draws)
        out = np.broadcast_to(a[0], (*ph.shape, k, draws)).copy()
        for m in b:
            out += (np.cos(m * ph)[..., None, None] * a[m]
                    + np.sin(m * ph)[..., None, None] * b[m])
        return out

    Y = np.einsum("qk,qjkd->qjd", Qt, c_at(phr)) + np.sqrt(eta) * rng.standard_normal(
        (*phr.shape, draws))
    fit = solve_joint(Y, Qt, phr, P, eta)
    return fit.coef - np.moveaxis(c_at(geo.PH_GRID), 0, 1)


@pytest.mark.parametrize(("n", "k"), [(1, 2), (3, 8)])
def test_aliasing_noise_matches_monte_carlo_of_the_joint_fit(n: int, k: int) -> None:
    """Harmonic 6 folds onto harmonic 2 at r = 8. Draw functions with harmonics 0, 2 and 6,
    read them at 8 uniform angles, fit with ``solve_joint`` (which knows all three): the
    W-weighted error of the fit's harmonics 0 and 2 is the model's with the folded prior as
    extra noise (exact for one pair; different pairs see the fold at different phases, which
    the model counts as independent noise), and clearly above the model without aliasing."""
    rng = np.random.default_rng(3 + n)
    r, eta, draws = 8, 0.05, 4000
    P = np.zeros((N_HARMONICS, k, k))
    P[0], P[2], P[6] = _spd(k, rng), _spd(k, rng), 0.5 * _spd(k, rng)
    W = _spd(k, rng)
    Qt = rng.standard_normal((n, k))
    ph_lab = rng.uniform(0, 2 * np.pi, n)
    alpha = np.arange(r) * 2 * np.pi / r
    phr = ph_lab[:, None] - alpha[None, :]
    err = _harmonic_error(_fit_errors(P, (0, 2, 6), Qt, phr, eta, draws, rng), [0, 2])
    mc = float(np.mean(np.einsum("ksd,kl,lsd->sd", err, W, err)))
    noise = np.array([eta / r, 2 * eta / r])
    aliased = PriorModel(np.stack([P[0], P[2]]), np.array([0, 2]), noise, W,
                         alias=np.stack([np.zeros((k, k)), P[6]]))
    plain = PriorModel(np.stack([P[0], P[2]]), np.array([0, 2]), noise, W)
    assert expected_error(aliased, Qt) == pytest.approx(mc, rel=0.05 if n == 1 else 0.15)
    assert expected_error(plain, Qt) < 0.9 * mc


def test_prior_model_folds_the_unresolved_harmonics() -> None:
    """r = 8 resolves 0..3; 5 -> 3, 6 -> 2, 7 -> 1, 8 -> 0, 9 -> 1, ...; 4 and 12 (Nyquist)
    fold onto none."""
    assert [folded_onto(m, 8) for m in range(13)] == [0, 1, 2, 3, None, 3, 2, 1, 0, 1, 2, 3,
                                                      None]
    assert [folded_onto(m, 5) for m in range(7)] == [0, 1, 2, 2, 1, 0, 1]
    b = _with_prior(random_basis(3), {0: 1.0, 2: 0.5, 6: 0.25, 10: 0.125, 12: 2.0})
    model = prior_model(b, 8, lam=0.0, aliasing=True, span_deg=360.0)
    assert model.harmonics.tolist() == [0, 2]
    assert model.alias is not None
    np.testing.assert_allclose(model.alias[0], 0.0)
    np.testing.assert_allclose(model.alias[1], (0.25 + 0.125) * np.eye(3))
    assert prior_model(b, 8).alias is None  # off by default
    # Over half a turn, 8 angles see harmonic 2 j as a full turn's 8 see j: 0, 2, 4, 6 are
    # resolved (4 carries nothing here); 10 (j = 5) folds onto j = 3, i.e. 6; 12 (j = 6) onto
    # j = 2, i.e. 4, which has no prior to absorb it.
    half = prior_model(b, 8, lam=0.0, aliasing=True, span_deg=180.0)
    assert half.harmonics.tolist() == [0, 2, 6]
    eta = 40.0  # the joint fit's default
    np.testing.assert_allclose(half.noise, [eta / 8, 2 * eta / 8, 2 * eta / 8])
    assert half.alias is not None
    np.testing.assert_allclose(half.alias[:2], 0.0)
    np.testing.assert_allclose(half.alias[2], 0.125 * np.eye(3))


def test_half_turn_noise_model_matches_monte_carlo_of_the_joint_fit() -> None:
    """Harmonics 0, 2 and 6 read at 8 angles over half a turn: ``prior_model``'s noise per
    harmonic (``eta / r``, ``2 eta / r``: over half a turn harmonic 6 is resolved, where a full
    turn's 8 angles would alias it onto 2) gives the W-weighted error of ``solve_joint``."""
    rng = np.random.default_rng(11)
    k, n, r, eta, draws = 4, 3, 8, 0.5, 4000
    b = _with_prior(random_basis(k), {0: 1.0, 2: 0.5, 6: 0.25})
    model = prior_model(b, r, eta=eta, lam=0.0, span_deg=180.0)
    assert model.harmonics.tolist() == [0, 2, 6]
    P = np.asarray(b.ph_prior)
    W = _spd(k, rng)
    Qt = rng.standard_normal((n, k))
    ph_lab = rng.uniform(0, 2 * np.pi, n)
    alpha = np.arange(r) * np.pi / r
    phr = ph_lab[:, None] - alpha[None, :]
    err = _fit_errors(P, (0, 2, 6), Qt, phr, eta, draws, rng)
    mc = float(np.mean(np.einsum("ksd,kl,lsd->sd", err, W, err)))
    same = PriorModel(model.P, model.harmonics, model.noise, W)
    assert expected_error(same, Qt) == pytest.approx(mc, rel=0.05)


def test_prior_model_refuses_other_arcs() -> None:
    b = _with_prior(random_basis(3), {0: 1.0, 2: 0.5})
    with pytest.raises(DesignError, match="180 or 360"):
        prior_model(b, 8, span_deg=90.0)
