"""Tests of the joint fit's posterior: expected error and adaptive refinement (issue 9.4)."""

from __future__ import annotations

import numpy as np
import pytest

from gonio.brdf.reconstruction.posterior import (
    QUARTERS,
    RHO_GRID,
    ScanPosterior,
    candidate_angles,
    next_angles,
)
from gonio.brdf.reconstruction.reconstruct import ReconstructionError
from gonio.brdf.tables import geometry as geo
from tests.unit.brdf.reconstruction.test_reconstruct import grid_pairs, random_basis
from tests.unit.brdf.reconstruction.test_reconstruct_joint import _with_prior

HARMONICS = {0: 1.0, 2: 1.0, 4: 0.5, 36: 0.2}


def _scan(seed: int = 3) -> tuple[object, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    b = _with_prior(random_basis(6, seed=1), HARMONICS)
    cells, ph = grid_pairs(5, seed=4)
    alpha = np.deg2rad([0.0, 45.0, 90.0, 180.0, 270.0])
    vals = np.abs(np.random.default_rng(seed).normal(1.0, 0.1, (5, 5, 1)))
    return b, cells, ph, alpha, vals


def _dense_weighted_variance(post: ScanPosterior, alpha: np.ndarray, tau: float = 0.0) -> float:
    """sum over the 72 slices of tr(W Cov_post(c(ph))), from the explicit Gaussian process
    (every covariance written out per slice and per reading; no harmonic shortcuts). ``tau``:
    each pair's readings share an offset of that variance, independent of the coefficients."""
    P = np.asarray(post.P)
    rho_m = np.where(np.arange(P.shape[0]) > 0, post.rho, 1.0)
    Qt = post.Qt
    ph_read = (post.ph_lab[:, None] - alpha[None, :]).ravel()
    q = np.repeat(np.arange(Qt.shape[0]), alpha.size)

    def prior(d: float) -> np.ndarray:  # Cov(c(ph), c(ph + d))
        return sum(rho_m[m] * P[m] * np.cos(m * d) for m in range(P.shape[0]))

    N = ph_read.size
    G = np.empty((N, N))
    for a in range(N):
        for b in range(N):
            G[a, b] = Qt[q[a]] @ prior(ph_read[a] - ph_read[b]) @ Qt[q[b]]
            G[a, b] += tau if q[a] == q[b] else 0.0
    G += post.eta * np.eye(N)
    total = 0.0
    for s in geo.PH_GRID:
        k = np.stack([prior(s - ph_read[a]) @ Qt[q[a]] for a in range(N)], axis=1)  # (K, N)
        cov = prior(0.0) - k @ np.linalg.solve(G, k.T)
        total += float(np.trace(post.W @ cov))
    return total


def test_weighted_variance_equals_the_explicit_posterior() -> None:
    b, cells, ph, alpha, vals = _scan()
    post = ScanPosterior(b, cells, ph, alpha, vals, lam=0.0, rho=2.0)
    assert post.weighted_variance() == pytest.approx(_dense_weighted_variance(post, alpha),
                                                     rel=1e-8)


def test_uncovered_share_is_the_explicit_posterior_over_the_prior() -> None:
    """The coverage witness: the posterior's weighted variance over the prior's, both from
    the explicit Gaussian process (the prior's: 72 slices of tr(W Cov(c(ph), c(ph))))."""
    b, cells, ph, alpha, vals = _scan()
    post = ScanPosterior(b, cells, ph, alpha, vals, lam=0.0, rho=2.0)
    P = np.asarray(post.P)
    rho_m = np.where(np.arange(P.shape[0]) > 0, post.rho, 1.0)
    prior = geo.N_PH * float(np.trace(post.W @ np.tensordot(rho_m, P, axes=1)))
    assert post.prior_weighted_variance() == pytest.approx(prior, rel=1e-10)
    share = _dense_weighted_variance(post, alpha) / prior
    assert 0.0 < share < 1.0
    assert post.uncovered_share() == pytest.approx(share, rel=1e-8)


def test_readings_drowned_in_noise_leave_everything_uncovered() -> None:
    """With a reading noise far above the prior's variance the readings say nothing: the
    posterior is the prior and the share is 1; more stage angles never raise it."""
    b, cells, ph, alpha, vals = _scan()
    assert ScanPosterior(b, cells, ph, alpha, vals, eta=1e9, lam=1e-3,
                         rho=1.0).uncovered_share() == pytest.approx(1.0, abs=1e-6)
    fewer = ScanPosterior(b, cells, ph, alpha[:3], vals[:, :3], lam=0.0, rho=1.0)
    more = ScanPosterior(b, cells, ph, alpha, vals, lam=0.0, rho=1.0)
    assert more.uncovered_share() < fewer.uncovered_share()


def test_angle_gain_is_the_variance_drop_of_reading_there() -> None:
    """The gain of a candidate equals the drop of the explicit posterior variance after
    conditioning on every pair read at that angle."""
    b, cells, ph, alpha, vals = _scan()
    post = ScanPosterior(b, cells, ph, alpha, vals, lam=0.0, rho=2.0)
    before = _dense_weighted_variance(post, alpha)
    cand = np.deg2rad([22.5, 135.0, 300.0])
    gains = post.angle_gains(cand)
    for g, beta in zip(gains, cand, strict=True):
        after = _dense_weighted_variance(post, np.concatenate([alpha, [beta]]))
        assert g == pytest.approx(before - after, rel=1e-7)


def test_with_a_per_pair_offset_the_variance_and_gains_are_the_explicit_posteriors() -> None:
    """A per-pair offset of variance tau (shared by every reading of one pair, whatever the
    stage angle, and no part of the table): the weighted variance and each candidate's gain
    equal the explicit posterior's with tau added where two readings are of one pair."""
    b, cells, ph, alpha, vals = _scan()
    tau = 0.7
    post = ScanPosterior(b, cells, ph, alpha, vals, lam=0.0, rho=2.0, offset=tau)
    before = _dense_weighted_variance(post, alpha, tau)
    assert post.weighted_variance() == pytest.approx(before, rel=1e-8)
    cand = np.deg2rad([22.5, 135.0])
    for g, beta in zip(post.angle_gains(cand), cand, strict=True):
        after = _dense_weighted_variance(post, np.concatenate([alpha, [beta]]), tau)
        assert g == pytest.approx(before - after, rel=1e-7)
    post.add_angles(cand[:1])
    assert post.weighted_variance() == pytest.approx(
        _dense_weighted_variance(post, np.concatenate([alpha, cand[:1]]), tau), rel=1e-8)


def test_an_offset_lowers_what_more_angles_buy_an_isotropic_scan() -> None:
    """With an isotropic prior every stage angle reads the same slice values, so a new angle
    only averages noise; an offset each pair keeps at every angle does not average away, so
    the same angle buys less the larger the offset."""
    b = _with_prior(random_basis(6, seed=1), {0: 1.0})
    cells, ph = grid_pairs(5, seed=4)
    alpha = np.deg2rad([0.0, 45.0, 90.0, 135.0])
    vals = np.abs(np.random.default_rng(3).normal(1.0, 0.1, (5, 4, 1)))
    gains = [float(ScanPosterior(b, cells, ph, alpha, vals, rho=1.0, offset=t)
                   .angle_gains(np.deg2rad([22.5]))[0]) for t in (0.0, 0.1, 1.0)]
    assert gains[0] > gains[1] > gains[2] > 0


def test_the_scans_offset_is_the_likelihood_maximum() -> None:
    """offset='scan' picks the (rho, tau) of RHO_GRID x OFFSET_GRID whose Gaussian likelihood
    (scipy's multivariate normal on the covariance written out, the scale at its maximum) is
    largest; readings drawn with large per-pair offsets get a tau > 0."""
    from scipy.stats import multivariate_normal

    from gonio.brdf.reconstruction.posterior import OFFSET_GRID

    b, cells, ph, alpha, _ = _scan()
    rng = np.random.default_rng(11)
    base = np.abs(rng.normal(1.0, 0.05, (5, 1, 2)))
    vals = base * np.exp(rng.normal(0.0, 0.5, (5, 1, 2))) * np.ones((5, alpha.size, 1))
    vals *= np.exp(rng.normal(0.0, 0.01, vals.shape))
    post = ScanPosterior(b, cells, ph, alpha, vals, lam=0.0, offset="scan")
    y = post.y
    N, C = y.shape
    q = np.repeat(np.arange(5), alpha.size)
    same = (q[:, None] == q[None, :]).astype(float)
    # The offsets' unit: the mean prior variance of one reading (isotropic part).
    unit = float(np.mean(np.diag(_dense_prior_readings(post, alpha, 0.0, 0.0))))
    best, best_ll = None, -np.inf
    for r in RHO_GRID:
        K = _dense_prior_readings(post, alpha, r, r)
        for f in OFFSET_GRID:
            G = K + f * unit * same + post.eta * np.eye(N)
            s2 = float(np.sum(y * np.linalg.solve(G, y))) / (N * C)
            ll = sum(multivariate_normal(np.zeros(N), s2 * G).logpdf(y[:, c]) for c in range(C))
            if ll > best_ll:
                best, best_ll = (r, f * unit), ll
    assert best is not None and best[1] > 0
    assert (post.rho, post.tau) == pytest.approx(best, rel=1e-9)


def test_refinement_picks_the_angle_with_the_largest_posterior_variance() -> None:
    """Angles crowded in one quarter leave a 270 degree gap: one new angle goes where the
    explicit posterior variance drops most, and that is inside the big gap (quarter points as
    candidates: the midpoints here are 45 degrees apart modulo 180, which this prior's even
    harmonics cannot tell apart)."""
    b, cells, ph, _, _ = _scan()
    alpha_deg = np.array([0.0, 30.0, 60.0, 90.0])
    vals = np.abs(np.random.default_rng(5).normal(1.0, 0.2, (5, 4, 1)))
    step = next_angles(b, cells, ph, alpha_deg, vals, threshold=0.0, batch=1,
                       fractions=QUARTERS)
    assert len(step.angles_deg) == 1
    post = ScanPosterior(b, cells, ph, np.deg2rad(alpha_deg), vals, rho=step.rho)
    cand = candidate_angles(alpha_deg, 1.0, QUARTERS)
    before = _dense_weighted_variance(post, np.deg2rad(alpha_deg))
    drops = [before - _dense_weighted_variance(post, np.deg2rad(np.append(alpha_deg, c)))
             for c in cand]
    assert step.angles_deg[0] == pytest.approx(cand[int(np.argmax(drops))])
    assert 90.0 < step.angles_deg[0] < 360.0


def test_rho_follows_the_material() -> None:
    """Readings constant along ph (an isotropic material) choose the smallest anisotropy
    factor; readings that swing strongly with ph choose a larger one."""
    b = _with_prior(random_basis(6, seed=1), HARMONICS)
    cells, ph = grid_pairs(6, seed=4)
    alpha = np.deg2rad(np.arange(0.0, 360.0, 30.0))
    rng = np.random.default_rng(0)
    iso = np.repeat(rng.uniform(0.5, 2.0, (6, 1, 1)), alpha.size, axis=1)
    phr = ph[:, None] - alpha[None, :]
    aniso = iso * np.exp(1.5 * np.cos(2 * phr))[..., None]
    assert ScanPosterior(b, cells, ph, alpha, iso).rho == RHO_GRID[0]
    assert ScanPosterior(b, cells, ph, alpha, aniso).rho > RHO_GRID[0]


def test_the_plan_stops_when_the_rule_says() -> None:
    b, cells, ph, alpha, vals = _scan()
    deg = np.rad2deg(alpha)
    high = next_angles(b, cells, ph, deg, vals, threshold=1e9)
    assert high.angles_deg == [] and high.reason == "threshold"
    broke = next_angles(b, cells, ph, deg, vals, threshold=0.0, budget_angles=0)
    assert broke.angles_deg == [] and broke.reason == "budget"
    fine = next_angles(b, cells, ph, deg, vals, threshold=0.0, min_step_deg=100.0)
    assert fine.angles_deg == [] and fine.reason == "min_step"
    two = next_angles(b, cells, ph, deg, vals, threshold=0.0, budget_angles=2)
    assert len(two.angles_deg) == 2 and two.reason == ""
    assert all(d >= 0 for d in two.drops) and two.drops[0] >= two.drops[1]


def test_candidates_respect_the_stage_resolution() -> None:
    """The midpoints of the gaps (90 and 270 degrees here) by default, or the quarter, half
    and three-quarter points, minus those closer than the stage resolution to a measured
    angle."""
    np.testing.assert_allclose(candidate_angles([0.0, 90.0], 1.0), [45.0, 225.0])
    np.testing.assert_allclose(candidate_angles([0.0, 90.0], 1.0, QUARTERS),
                               [22.5, 45.0, 67.5, 157.5, 225.0, 292.5])
    np.testing.assert_allclose(candidate_angles([0.0, 90.0], 30.0, QUARTERS),
                               [45.0, 157.5, 225.0, 292.5])
    np.testing.assert_allclose(candidate_angles([0.0, 90.0], 50.0), [225.0])
    assert candidate_angles([0.0, 1.0], 200.0).size == 0


def test_fully_refined_midpoints_are_the_uniform_grid() -> None:
    """From 4 uniform angles, two rounds of one midpoint per gap give uniform 16 (what the
    rule's goal is measured against, and the dry run's worst case)."""
    b, cells, ph, _, _ = _scan()
    deg = [0.0, 90.0, 180.0, 270.0]
    vals = np.abs(np.random.default_rng(2).normal(1.0, 0.1, (5, 4, 1)))
    for _ in range(2):
        step = next_angles(b, cells, ph, deg, vals, threshold=0.0, per_gap=1)
        deg = sorted(deg + step.angles_deg)
        vals = np.abs(np.random.default_rng(len(deg)).normal(1.0, 0.1, (5, len(deg), 1)))
    np.testing.assert_allclose(deg, np.arange(16) * 22.5)


def test_half_turn_candidates_halve_the_gaps_of_the_half_turn() -> None:
    """Over half a turn the angles 0, 45, 90, 135 have four 45 degree gaps (the last one from
    135 to 180, where the scan's first angle reads again): their midpoints are the odd
    multiples of 22.5 in the half turn, not 247.5 in the full turn's 225 degree gap. An arc
    that starts at 270 (270..360 and 0..90) keeps its candidates there."""
    np.testing.assert_allclose(candidate_angles([0.0, 45.0, 90.0, 135.0], 1.0, period_deg=180.0),
                               [22.5, 67.5, 112.5, 157.5])
    np.testing.assert_allclose(
        candidate_angles([270.0, 315.0, 0.0, 45.0], 1.0, period_deg=180.0, arc_start_deg=270.0),
        [22.5, 67.5, 292.5, 337.5])
    # A reading half a turn away is the same position: 0 and 180 are one angle of the arc.
    np.testing.assert_allclose(candidate_angles([0.0, 180.0, 90.0], 1.0, period_deg=180.0),
                               [45.0, 135.0])
    # The stage resolution against the half turn's gaps (45: midpoints 22.5 away).
    assert candidate_angles([0.0, 45.0, 90.0, 135.0], 23.0, period_deg=180.0).size == 0


def test_half_turn_refinement_reaches_uniform_16_over_the_half_turn() -> None:
    """From 4 uniform angles over half a turn, two rounds of one midpoint per gap give the 16
    uniform angles 11.25 k of the half turn (uniform 16 over 180 degrees, the reference of
    half-turn plans); every round's angles lie in [0, 180)."""
    b, cells, ph, _, _ = _scan()
    deg = [0.0, 45.0, 90.0, 135.0]
    vals = np.abs(np.random.default_rng(2).normal(1.0, 0.1, (5, 4, 1)))
    for _ in range(2):
        step = next_angles(b, cells, ph, deg, vals, threshold=0.0, per_gap=1, period_deg=180.0)
        assert len(step.angles_deg) == len(deg) and all(0 <= a < 180 for a in step.angles_deg)
        deg = sorted(deg + step.angles_deg)
        vals = np.abs(np.random.default_rng(len(deg)).normal(1.0, 0.1, (5, len(deg), 1)))
    np.testing.assert_allclose(deg, np.arange(16) * 11.25)


def test_the_rule_stops_at_the_gain_it_is_given() -> None:
    """The expected drops of the greedy picks, from a run without a threshold, decide a run
    with one: a threshold between the second and the first drop plans exactly one angle, at
    the first drop itself too (at least), just above it none; likewise for the relative rule
    against the expected error left before each pick."""
    b, cells, ph, alpha, vals = _scan()
    deg = np.rad2deg(alpha)
    free = next_angles(b, cells, ph, deg, vals, threshold=0.0, budget_angles=3)
    d = free.drops
    assert len(d) == 3 and d[0] > d[1] > 0
    first = next_angles(b, cells, ph, deg, vals, threshold=0.0, budget_angles=1)
    one = next_angles(b, cells, ph, deg, vals, threshold=0.5 * (d[0] + d[1]))
    assert len(first.angles_deg) == 1 and one.angles_deg == first.angles_deg
    assert one.drops == pytest.approx([d[0]]) and one.reason == ""
    assert len(next_angles(b, cells, ph, deg, vals, threshold=d[0]).angles_deg) == 1
    none = next_angles(b, cells, ph, deg, vals, threshold=d[0] * (1 + 1e-9))
    assert none.angles_deg == [] and none.reason == "threshold"
    # Relative: the first pick's drop is d[0] / e0 of the expected error e0.
    f0 = d[0] / free.expected_log_rmse
    rel = next_angles(b, cells, ph, deg, vals, threshold=0.0, rel_threshold=f0 * (1 + 1e-9))
    assert rel.angles_deg == [] and rel.reason == "threshold"
    assert next_angles(b, cells, ph, deg, vals, threshold=0.0, rel_threshold=f0 * (1 - 1e-9),
                       budget_angles=1).angles_deg == one.angles_deg


def test_with_the_scans_cv_the_drop_is_that_of_the_self_estimate() -> None:
    """Given the leave-one-pair-out error, a pick's drop is the fall of the self-estimate
    ``sqrt(exp(a) e^2 + exp(b) m^c cv^d)`` (the selfcheck module's formula, written out here)
    as the posterior's expected error ``e`` falls by the pick's own drop: the same angle is
    picked, the drop is smaller the more the basis cannot represent, and with nothing
    unrepresented it is ``sqrt(exp(a))`` times the posterior's own."""
    from gonio.brdf.reconstruction.selfcheck import LOG_RMSE_CAPS, LOG_RMSE_MODEL

    b, cells, ph, alpha, vals = _scan()
    deg = np.rad2deg(alpha)
    plain = next_angles(b, cells, ph, deg, vals, threshold=0.0, budget_angles=1)
    e0 = plain.expected_log_rmse
    e1 = e0 - plain.drops[0]
    mahal = ScanPosterior(b, cells, ph, alpha, vals).mahalanobis
    a, bb, c, d = LOG_RMSE_MODEL

    def self_estimate(e: float, cv: float) -> float:
        m = min(mahal, LOG_RMSE_CAPS[0])
        return float(np.sqrt(np.exp(a) * e**2 + np.exp(bb) * m**c * min(cv, LOG_RMSE_CAPS[1])**d))

    drops = []
    for cv in (1e-9, 0.05, 0.5):
        step = next_angles(b, cells, ph, deg, vals, threshold=0.0, budget_angles=1,
                           cv_sample_error=cv)
        assert step.angles_deg == plain.angles_deg
        assert step.drops[0] == pytest.approx(self_estimate(e0, cv) - self_estimate(e1, cv),
                                              rel=1e-6)
        drops.append(step.drops[0])
    assert drops[0] == pytest.approx(np.sqrt(np.exp(a)) * plain.drops[0], rel=1e-3)
    assert drops[0] > drops[1] > drops[2] > 0
    # The threshold applies to that drop: just above it, no angle.
    none = next_angles(b, cells, ph, deg, vals, threshold=drops[2] * (1 + 1e-9),
                       cv_sample_error=0.5)
    assert none.angles_deg == [] and none.reason == "threshold"


def test_bad_readings_are_refused() -> None:
    b, cells, ph, alpha, vals = _scan()
    with pytest.raises(ReconstructionError, match="non-negative"):
        ScanPosterior(b, cells, ph, alpha, -vals)
    with pytest.raises(ReconstructionError, match="expected"):
        ScanPosterior(b, cells, ph, alpha, vals[:, :3])


def test_one_angle_per_gap_when_asked() -> None:
    """per_gap=1: however many angles pass the threshold, each gap between the measured
    angles gets at most one (the dry run's bound assumes midpoint-like rounds)."""
    b, cells, ph, alpha, vals = _scan()
    deg = np.rad2deg(alpha)  # gaps of 45, 45, 90, 90, 90 degrees
    step = next_angles(b, cells, ph, deg, vals, threshold=0.0, budget_angles=20, per_gap=1)
    edges = np.sort(np.mod(deg, 360.0))
    gap = np.searchsorted(edges, step.angles_deg, side="right") - 1
    assert len(step.angles_deg) == 5 and sorted(set(gap.tolist())) == [0, 1, 2, 3, 4]


def test_reconstruct_with_rho_is_the_fit_under_the_scaled_prior() -> None:
    """``reconstruct(..., rho=r)`` is the joint fit under a prior whose varying harmonics are
    r times the learnt ones: the same as a basis built with that prior (lam = 0, so the
    specular condition does not touch the prior)."""
    from gonio.brdf.reconstruction.reconstruct import reconstruct

    b, cells, ph, alpha, vals = _scan()
    scaled = _with_prior(random_basis(6, seed=1),
                         {m: (v if m == 0 else 0.125 * v) for m, v in HARMONICS.items()})
    got = reconstruct(b, cells, ph, alpha, vals, channels=("Y",), lam=0.0, rho=0.125)
    want = reconstruct(scaled, cells, ph, alpha, vals, channels=("Y",), lam=0.0, rho=None)
    np.testing.assert_allclose(got.coefficients, want.coefficients, rtol=1e-9, atol=1e-12)
    plain = reconstruct(b, cells, ph, alpha, vals, channels=("Y",), rho=None)
    same = reconstruct(b, cells, ph, alpha, vals, channels=("Y",), rho=1.0)
    np.testing.assert_array_equal(plain.coefficients, same.coefficients)
    for bad in (0.0, -1.0, float("nan")):
        with pytest.raises(ReconstructionError, match="rho"):
            reconstruct(b, cells, ph, alpha, vals, channels=("Y",), rho=bad)


def test_the_fit_takes_the_scans_own_anisotropy_only_when_it_is_smaller() -> None:
    """Readings constant along ph: the marginal likelihood is largest for the smallest rho
    (nothing varies with the stage angle), and the default fit uses it, so the slices barely
    vary along ph; readings that swing with ph keep the learnt prior (factor 1)."""
    from gonio.brdf.reconstruction.reconstruct import SCAN_RHO_MAX, reconstruct

    b = _with_prior(random_basis(6, seed=1), HARMONICS)
    cells, ph = grid_pairs(6, seed=4)
    alpha = np.deg2rad(np.arange(0.0, 360.0, 90.0))
    rng = np.random.default_rng(0)
    iso = np.repeat(rng.uniform(0.5, 2.0, (6, 1, 1)), alpha.size, axis=1)
    rec = reconstruct(b, cells, ph, alpha, iso, channels=("Y",))
    assert rec.settings["prior_rho"] == RHO_GRID[0] < SCAN_RHO_MAX
    assert rec.table.provenance["reconstruction"]["prior_rho"] == RHO_GRID[0]
    want = reconstruct(b, cells, ph, alpha, iso, channels=("Y",), rho=RHO_GRID[0])
    np.testing.assert_array_equal(rec.coefficients, want.coefficients)
    plain = reconstruct(b, cells, ph, alpha, iso, channels=("Y",), rho=None)
    assert plain.settings["prior_rho"] == 1.0
    spread = np.ptp(rec.coefficients[0], axis=1).max()
    assert spread < 0.5 * np.ptp(plain.coefficients[0], axis=1).max()

    phr = ph[:, None] - alpha[None, :]
    aniso = iso * np.exp(1.5 * np.cos(2 * phr))[..., None]
    rec = reconstruct(b, cells, ph, alpha, aniso, channels=("Y",))
    assert rec.settings["prior_rho"] == 1.0
    np.testing.assert_array_equal(
        rec.coefficients,
        reconstruct(b, cells, ph, alpha, aniso, channels=("Y",), rho=None).coefficients)


def _dense_prior_readings(post: ScanPosterior, alpha: np.ndarray, low: float,
                          high: float) -> np.ndarray:
    """The readings' prior covariance written out element by element (no harmonic tricks)."""
    from gonio.brdf.reconstruction.posterior import BAND_SPLIT

    P = np.asarray(post.P)
    scale = [1.0 if m == 0 else low if m <= BAND_SPLIT else high for m in range(P.shape[0])]
    ph_read = (post.ph_lab[:, None] - alpha[None, :]).ravel()
    q = np.repeat(np.arange(post.Qt.shape[0]), alpha.size)
    N = ph_read.size
    G = np.empty((N, N))
    for a in range(N):
        for b_ in range(N):
            d = ph_read[a] - ph_read[b_]
            Pd = sum(scale[m] * P[m] * np.cos(m * d) for m in range(P.shape[0]))
            G[a, b_] = post.Qt[q[a]] @ Pd @ post.Qt[q[b_]]
    return G


def test_log_marginal_is_the_gaussian_likelihood_with_the_scale_profiled() -> None:
    """log_marginal(low, high) + const is the log density of the readings under
    N(0, s2 (G + eta I)) at the maximising s2 = y^T (G + eta I)^-1 y / (N C), per channel
    (scipy's multivariate normal on the covariance written out element by element)."""
    from scipy.stats import multivariate_normal

    b, cells, ph, alpha, _ = _scan()
    vals = np.abs(np.random.default_rng(8).normal(1.0, 0.3, (5, 5, 2)))
    post = ScanPosterior(b, cells, ph, alpha, vals, lam=0.0)
    y = post.y
    N, C = y.shape
    for low, high in ((0.25, 4.0), (2.0, 0.125), (1.0, 1.0)):
        G = _dense_prior_readings(post, alpha, low, high) + post.eta * np.eye(N)
        s2 = float(np.sum(y * np.linalg.solve(G, y))) / (N * C)
        want = sum(multivariate_normal(np.zeros(N), s2 * G).logpdf(y[:, c]) for c in range(C))
        const = -0.5 * N * C * (1.0 + np.log(2 * np.pi))
        assert post.log_marginal(low, high) + const == pytest.approx(want, rel=1e-9)


def test_band_factors_recover_the_spectrum_the_readings_were_drawn_from() -> None:
    """Many channels drawn from the joint fit's own model with the low band's factor 4 and
    the high band's 1/16: the marginal likelihood over the grid picks those (one grid step
    each way at most), where a single factor cannot. Isotropic readings take the bottom of
    the grid in both bands."""
    from gonio.brdf.reconstruction.posterior import BAND_SPLIT

    b = _with_prior(random_basis(6, seed=1), {0: 1.0, 2: 1.0, 4: 1.0, 6: 1.0})
    cells, ph = grid_pairs(6, seed=4)
    alpha = np.deg2rad(np.arange(0.0, 360.0, 30.0))
    template = np.ones((6, alpha.size, 1))
    post = ScanPosterior(b, cells, ph, alpha, template, lam=0.0, rho=1.0)
    assert BAND_SPLIT == 2
    G = _dense_prior_readings(post, alpha, 4.0, 1 / 16) + post.eta * np.eye(6 * alpha.size)
    rng = np.random.default_rng(5)
    y = np.linalg.cholesky(G) @ rng.standard_normal((G.shape[0], 200))
    # Readings whose remapped, centred values are y: undo the remap of each pair's row.
    from gonio.brdf.reconstruction.basis import inverse_remap

    th, td, pd = cells.T
    rows, weights = b.neighbours(th, td, pd)
    fmed = (weights * b.f_med[rows]).sum(axis=1)[:, None, None]
    mu = (weights * b.mu[rows]).sum(axis=1)[:, None, None]
    ci, co = geo.cell_cosines(th, td, pd)
    w = np.maximum(ci * co, b.eps)[:, None, None]
    vals = inverse_remap(0.05 * y.reshape(6, alpha.size, -1) + mu, fmed, w, b.eps)
    banded = ScanPosterior(b, cells, ph, alpha, vals, lam=0.0, bands=True)
    step = np.log(RHO_GRID[1] / RHO_GRID[0])
    assert abs(np.log(banded.rho / 4.0)) <= step + 1e-9
    assert abs(np.log(banded.rho_high * 16.0)) <= step + 1e-9
    flat = ScanPosterior(b, cells, ph, alpha, vals, lam=0.0)
    assert flat.rho == flat.rho_high
    assert banded.log_marginal(banded.rho, banded.rho_high) > flat.log_marginal(flat.rho)

    iso = np.repeat(np.random.default_rng(0).uniform(0.5, 2.0, (6, 1, 1)), alpha.size, axis=1)
    both = ScanPosterior(b, cells, ph, alpha, iso, bands=True)
    assert both.rho == both.rho_high == RHO_GRID[0]


def test_reconstruct_with_two_factors_is_the_fit_under_the_rescaled_bands() -> None:
    """``rho=(low, high)`` is the joint fit under a prior whose harmonic 2 is ``low`` times
    and harmonics 4 and 36 are ``high`` times the learnt ones (a basis built with that
    prior, lam = 0); ``"scan-bands"`` is the fit under the factors its posterior chose."""
    from gonio.brdf.reconstruction.reconstruct import reconstruct

    b, cells, ph, alpha, vals = _scan()
    scaled = _with_prior(random_basis(6, seed=1), {0: 1.0, 2: 3.0 * 1.0, 4: 0.25 * 0.5,
                                                   36: 0.25 * 0.2})
    got = reconstruct(b, cells, ph, alpha, vals, channels=("Y",), lam=0.0, rho=(3.0, 0.25))
    want = reconstruct(scaled, cells, ph, alpha, vals, channels=("Y",), lam=0.0, rho=None)
    np.testing.assert_allclose(got.coefficients, want.coefficients, rtol=1e-9, atol=1e-12)
    assert got.settings["prior_rho"] == 3.0 and got.settings["prior_rho_high"] == 0.25

    rec = reconstruct(b, cells, ph, alpha, vals, channels=("Y",), rho="scan-bands")
    post = ScanPosterior(b, cells, ph, alpha, vals, bands=True)
    pair = (post.rho, post.rho_high)
    assert (rec.settings["prior_rho"], rec.settings.get("prior_rho_high", pair[0])) == pair
    np.testing.assert_array_equal(
        rec.coefficients,
        reconstruct(b, cells, ph, alpha, vals, channels=("Y",), rho=pair).coefficients)
    for bad in ((1.0, 0.0), (1.0,), (1.0, float("inf")), "bands"):
        with pytest.raises(ReconstructionError, match="rho"):
            reconstruct(b, cells, ph, alpha, vals, channels=("Y",), rho=bad)  # type: ignore[arg-type]


def test_the_band_search_finds_the_grid_maximum_of_the_marginal_likelihood() -> None:
    """The low-rank search of the two bands' factors picks the pair of RHO_GRID where the
    plain (one Cholesky per pair) log marginal likelihood is largest."""
    b = _with_prior(random_basis(6, seed=1), {0: 1.0, 1: 0.3, 2: 1.0, 4: 0.5, 36: 0.2})
    cells, ph = grid_pairs(5, seed=4)
    alpha = np.deg2rad([0.0, 45.0, 90.0, 180.0, 270.0, 300.0])
    phr = ph[:, None] - alpha[None, :]
    for k, vals in enumerate((
            np.abs(np.random.default_rng(3).normal(1.0, 0.2, (5, 6, 2))),
            np.exp(0.8 * np.cos(2 * phr) + 0.3 * np.cos(4 * phr))[..., None] + 0.1,
            np.exp(0.1 * np.cos(2 * phr) + 0.8 * np.cos(4 * phr + 1.0))[..., None] + 0.1)):
        post = ScanPosterior(b, cells, ph, alpha, vals, lam=0.0, bands=True)
        lls = np.array([[post.log_marginal(lo, hi) for hi in RHO_GRID] for lo in RHO_GRID])
        i, j = np.unravel_index(int(np.argmax(lls)), lls.shape)
        assert (post.rho, post.rho_high) == (RHO_GRID[i], RHO_GRID[j]), k


def test_weights_from_every_third_slice_equal_those_from_the_whole_table() -> None:
    """The log_rmse weights read every third slice: given only those slices, the posterior is
    the same; W is the docstring's ``Q^T diag(wV g^2) Q`` with ``g^2`` averaged over channels
    and those slices (non-finite values counting as 0)."""
    from gonio.brdf.reconstruction.basis import row_weight
    from gonio.brdf.reconstruction.posterior import _cos_ti_rows, _volume_weight_rows
    from gonio.brdf.tables.table import VALID_ROWS

    b, cells, ph, alpha, _ = _scan()
    rng = np.random.default_rng(8)
    vals = np.abs(rng.normal(1.0, 0.1, (5, 5, 3)))
    table = np.where(geo.valid_mask()[None, None], rng.uniform(0, 3, (3, *geo.TABLE_SHAPE)),
                     np.nan)
    table[1, 3, 2, 4, 5] = np.inf  # a valid cell the weights must ignore
    whole = ScanPosterior(b, cells, ph, alpha, vals, table=table, rho=0.5)
    thin = ScanPosterior(b, cells, ph, alpha, vals, table=table[:, ::3], rho=0.5)
    np.testing.assert_allclose(thin.W, whole.W, rtol=1e-12)
    assert thin.expected_log_rmse == pytest.approx(whole.expected_log_rmse, rel=1e-12)
    f = table.reshape(3, geo.N_PH, geo.N_ROWS)[:, ::3][:, :, VALID_ROWS]
    f = np.where(np.isfinite(f), f, 0.0)
    ci = _cos_ti_rows()
    g = ci * (f + b.eps / row_weight(b.eps)[VALID_ROWS]) / (1 + f * ci)
    Qv = b.Q[VALID_ROWS]
    W = Qv.T @ (Qv * (_volume_weight_rows() * np.mean(g**2, axis=(0, 1)))[:, None])
    np.testing.assert_allclose(whole.W, W, rtol=1e-10)
    with pytest.raises(ReconstructionError, match="table has shape"):
        ScanPosterior(b, cells, ph, alpha, vals, table=table[:, :10], rho=0.5)


def test_the_fit_and_the_posteriors_share_one_default_eta() -> None:
    """reconstruct's joint fit, the scan posterior (its witnesses, the adaptive planning) and
    the design's prior model default to the same noise ratio, V&F's 40 (docs/science.md 2.1;
    7.2.4 says why 80 was not adopted): a split would make the self-estimate and the design
    describe a fit that is not the one run."""
    import inspect

    from gonio.brdf.design.posterior import prior_model
    from gonio.brdf.reconstruction.joint import JOINT_ETA
    from gonio.brdf.reconstruction.reconstruct import reconstruct

    b, cells, ph, alpha, vals = _scan()
    rec = reconstruct(b, cells, ph, alpha, vals, channels=("Y",))
    assert rec.settings["eta"] == JOINT_ETA == 40.0
    assert ScanPosterior(b, cells, ph, alpha, vals).eta == JOINT_ETA
    assert inspect.signature(prior_model).parameters["eta"].default == JOINT_ETA
