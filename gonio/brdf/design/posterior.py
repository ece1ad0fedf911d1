"""Pair designs chosen by the expected error of the joint fit (issue 9, item 3).

The condition number of the sampled basis rows (V&F Sec. 3.3,
:mod:`gonio.brdf.design.search`) says how well the rows separate the components; it knows
nothing of how likely each component is, of the rotations, or of the error a rendering sees.
The joint fit (:func:`gonio.brdf.reconstruction.joint.solve_joint`) has a Gaussian
prior, so the expected error of a design can be written down before any material is
measured, and a design can minimise it.

Model (math.md 6). Coefficients along ``ph``: ``c(ph) = a_0 + sum_m a_m cos(m ph) + b_m sin(m
ph)`` with ``Cov(a_0) = P_0`` and ``Cov(a_m) = Cov(b_m) = P_m`` (``sum_m P_m cos(m (ph -
ph'))`` is the prior's covariance; ``P_m`` the basis' learnt ``ph_prior`` with the specular
condition, :func:`gonio.brdf.reconstruction.joint.joint_prior`). A pair with basis row
``q`` read at ``r`` uniform stage angles with noise variance ``eta`` measures ``q^T a_0``
with variance ``eta / r`` and ``q^T a_m``, ``q^T b_m`` with variance ``2 eta / r`` each
(``sum_j cos^2 = r / 2``), for the harmonics ``0 < m < r / 2`` that ``r`` angles resolve.
The readings of different harmonics are orthogonal, so each harmonic's posterior is a ridge
update of its own: ``Sigma_m <- Sigma_m - Sigma_m q q^T Sigma_m / (q^T Sigma_m q + s_m)``.

Aliasing (``aliasing=True``; off by default). ``r`` angles cannot tell harmonic ``m'`` from the
one it folds onto, ``m = min(m' mod r, r - m' mod r)`` (``cos(m' (ph - 2 pi j / r))`` takes
the same values at the ``r`` angles as a harmonic-``m`` wave of the same amplitude), so the
harmonics ``r`` does not resolve add ``q^T A_m q`` to the noise of the pair's measurement of
``a_m``, ``A_m = sum_{m' -> m} P_m'`` (the Nyquist harmonic ``r / 2`` folds onto none). A
material whose value at the pair's cell turns fast with ``ph`` (a sharp anisotropic lobe)
then gives a noisier measurement of its slow part, as it does in the fit. Different pairs
see the folded part at different phases (their lab azimuths, placed after the choice), so it
is counted as independent noise per pair; for one pair this is the fit's exact posterior.

Error a rendering sees. The headline metric compares ``ln(1 + f cos ti)`` (Löw et al.) with
volume weights ``wV``; a change ``dx`` of the remapped value ``x = ln((f w + eps) / (f_med w +
eps))`` at a row changes it by ``s dx`` with ``s = cos ti (f w + eps) / (w (1 + f cos ti))``.
So the expected squared metric error, averaged over ``ph``, is ``sum_m tr(W Sigma_m)`` with
``W = sum_rows wV s^2 Q_row Q_row^T`` (:func:`metric_gram`), ``s`` taken at the row's median
``f_med`` (``slope="median"``, the default). ``s`` depends on the material's own value and
grows with it towards 1 (a glossy material's peak counts fully, a matte one's hardly), so
``slope="spread"`` replaces ``s^2`` by its mean ``E[s^2]`` over the values the basis' training
materials take at the row: ``x ~ N(mu, Q_row C Q_row^T)``, ``C = sum_m P_m / n_columns`` the
coefficients' covariance over the training columns, averaged with a Gauss-Hermite rule. Both
corrections (this and aliasing) are options: on held-out materials they did not lower the
error (``docs/science.md`` 7.2.1).

Other weightings of the cells (``cell_weight``, ``cell_mix``). ``wV`` is how ``log_rmse``
weighs cells; a picture weighs them by how many of its pixels look them up
(:func:`gonio.brdf.pictures.appearance.render_importance`: the standard renderings see a few
thousand cells, at ``td`` = half their lights' angles). :func:`cell_gram` is ``W`` with such a
map ``c`` in place of ``wV``, and the design can minimise ``(1 - a) W + a ratio W_c``, ``ratio``
making both weigh the prior alike (``docs/science.md`` 7.2.2: ``a = 0.5`` trades a few percent
of ``log_rmse`` for HDR-FLIP on the measured materials). This function takes no weighting
unless asked; :func:`gonio.brdf.design.pairs.design_pairs` asks for ``a = 0.5`` with the
shipped map (:mod:`gonio.brdf.design.renderweight`) by default.

Search: greedy, one pair at a time, each time the feasible cell that lowers
``sum_m tr(W Sigma_m)`` most (gain ``q^T Sigma_m W Sigma_m q / (q^T Sigma_m q + s_m)``, for
every candidate at once). Exchange passes after the greedy start lowered the objective
further but not the error on the unseen materials (``docs/science.md`` 7.2), so there are
none. When devices can collide, each step takes the best cell with which the pairs chosen so
far still mount (:func:`~gonio.brdf.design.placement.place_pairs`, a few orders tried); when
none of the best cells of a step mounts, :func:`~gonio.brdf.design.pairs.design_pairs` lets
the condition-number search (which plans mounts as it goes) make the design instead.

Expected log_rmse (:func:`design_expected_log_rmse`). ``ph_prior`` is the covariance of the training
coefficients times the number of training columns (``Basis.provenance["n_columns"]``), so the
prior of one material is ``P_m / n_columns``; with that scale the expected squared metric error
divided by ``sum wV`` over the valid cells (``log_rmse``'s denominator per slice) is an
expected ``log_rmse^2``: the error the readings leave inside the basis (what the basis cannot
represent is not in it).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from gonio.brdf.design.colourtargets import ColourTargets, colour_gram
from gonio.brdf.design.conditioning import condition_number
from gonio.brdf.design.constraints import RigConstraints, candidate_rows, rows_to_cells
from gonio.brdf.design.errors import DesignError, DesignTimeout, FeasibilityError
from gonio.brdf.design.pairdesign import GreedyStats, PairDesign
from gonio.brdf.design.placement import place_pairs
from gonio.brdf.reconstruction.basis import Basis, inverse_remap
from gonio.brdf.reconstruction.joint import JOINT_ETA, JOINT_LAM, joint_prior
from gonio.brdf.reconstruction.samples import DEFAULT_SPAN_DEG, SamplesError, span_periods
from gonio.brdf.tables import geometry as geo

FloatArray = NDArray[np.float64]

#: Stage angles the expected error assumes when none are given (the default scan).
DEFAULT_ROTATIONS = 8
#: Seeds pick the first pair among this many best single pairs (seed modulo this).
FIRST_RANKS = 64


#: Where the metric's slope ``s`` is taken at each row (module notes): averaged over the spread
#: of the training materials' values (``"spread"``) or at their median (``"median"``).
MetricSlope = Literal["spread", "median"]
#: Gauss-Hermite nodes of the ``"spread"`` average (``s^2`` is smooth in ``x``; 20 nodes agree
#: with 40 to well under 1 %).
SLOPE_NODES = 20


def metric_gram(basis: Basis, slope: MetricSlope = "median") -> FloatArray:
    """(K, K) ``W``: the headline metric's weight on coefficient errors (module notes).

    ``W = sum_rows wV E[s^2] Q_row^T Q_row`` over the valid grid rows, ``wV`` the volume weight
    (math.md 10) and ``s = cos ti (f w + eps) / (w (1 + f cos ti))`` the slope of ``ln(1 + f cos
    ti)`` with respect to the remapped value.

    Parameters
    ----------
    basis : Basis
    slope : {"spread", "median"}
        ``"spread"``: ``E[s^2]`` over the remapped values the basis' training materials take at
        the row, ``x ~ N(mu, Q_row C Q_row^T)`` with ``C = sum_m P_m / n_columns``
        (:attr:`Basis.ph_prior`, or ``I`` without one; ``n_columns`` from the provenance).
        ``"median"``: ``s^2`` at ``f = f_med``. A basis whose provenance does not say how many
        columns it summarises gets the median slope.

    Returns
    -------
    (K, K) float64, symmetric positive semi-definite.
    """
    rows, s2 = _row_slopes(basis, slope)
    Qv = np.asarray(basis.Q, dtype=float)[rows]
    wv = geo.volume_weight().ravel()[rows]
    return np.asarray((Qv * (wv * s2)[:, None]).T @ Qv)


def cell_gram(basis: Basis, cell_weight: ArrayLike, slope: MetricSlope = "median"
              ) -> FloatArray:
    """(K, K) ``W`` with the cells weighed by ``cell_weight`` instead of the volume weight.

    ``W = sum_rows c_row E[s^2] Q_row^T Q_row``, ``s`` as in :func:`metric_gram`: the same
    error in the remapped value costs what it costs ``ln(1 + f cos ti)`` at that cell, counted
    ``c_row`` times. With ``c`` the pixel counts of
    :func:`gonio.brdf.pictures.appearance.render_importance` this is the expected squared log
    error over the pixels of the standard renderings (``ph`` averaged) instead of over the
    hemispheres' volume.

    Parameters
    ----------
    basis : Basis
    cell_weight : (18, 18, 36) or (11664,) array_like, >= 0, finite
        Weight of each grid cell (invalid cells are left out).
    slope : {"spread", "median"}

    Returns
    -------
    (K, K) float64, symmetric positive semi-definite.

    Raises
    ------
    DesignError
        For a map of the wrong size, negative or non-finite weights, or no weight on any
        valid cell.
    """
    c = np.asarray(cell_weight, dtype=float).ravel()
    if c.size != geo.N_ROWS:
        raise DesignError(f"a cell weight map has one value per grid cell ({geo.N_ROWS}, "
                          f"shape {geo.SLICE_SHAPE}), got {c.size} values")
    if not np.all(np.isfinite(c)) or np.any(c < 0):
        raise DesignError("cell weights must be finite and >= 0")
    rows, s2 = _row_slopes(basis, slope)
    if not np.any(c[rows] > 0):
        raise DesignError("the cell weight map puts no weight on any valid cell")
    Qv = np.asarray(basis.Q, dtype=float)[rows]
    return np.asarray((Qv * (c[rows] * s2)[:, None]).T @ Qv)


def _row_slopes(basis: Basis, slope: MetricSlope) -> tuple[NDArray[np.intp], FloatArray]:
    """The valid rows and the metric's ``E[s^2]`` at each (:func:`metric_gram`)."""
    if slope not in ("spread", "median"):
        raise DesignError(f"slope must be 'spread' or 'median', not {slope!r}")
    rows = np.flatnonzero(basis.valid)
    ci, co = geo.cell_cosines(*geo.grid_angles())
    ci, co = ci.ravel()[rows], co.ravel()[rows]
    w = np.maximum(ci * co, basis.eps)
    f_med = np.asarray(basis.f_med, dtype=float)[rows]
    Qv = np.asarray(basis.Q, dtype=float)[rows]
    n_columns = float(basis.provenance.get("n_columns", 0.0) or 0.0)
    if slope == "median" or n_columns <= 0:
        s2 = (ci * (f_med * w + basis.eps) / (w * (1.0 + f_med * ci))) ** 2
    else:
        C = (np.eye(basis.K) if basis.ph_prior is None
             else np.asarray(basis.ph_prior, dtype=float).sum(axis=0)) / n_columns
        sd = np.sqrt(np.maximum(np.einsum("rk,kl,rl->r", Qv, C, Qv), 0.0))
        t, wt = np.polynomial.hermite.hermgauss(SLOPE_NODES)
        x = np.asarray(basis.mu, dtype=float)[rows, None] + np.sqrt(2.0) * sd[:, None] * t
        f = np.maximum(inverse_remap(x, f_med[:, None], w[:, None], basis.eps), 0.0)
        s = ci[:, None] * (f * w[:, None] + basis.eps) / (w[:, None] * (1.0 + f * ci[:, None]))
        s2 = (s**2) @ wt / np.sqrt(np.pi)
    return rows, np.asarray(s2, dtype=float)


@dataclass(frozen=True)
class PriorModel:
    """The per-harmonic priors and reading noise of a scan with ``r`` uniform angles.

    Attributes
    ----------
    P : (H, K, K) prior covariances of the harmonics ``r`` resolves (only non-zero ones)
    harmonics : (H,) int, their orders ``m``
    noise : (H,) variance of one pair's measurement of one harmonic (``eta / r`` for m = 0,
        ``2 eta / r`` otherwise)
    W : (K, K) :func:`metric_gram`
    scale : float
        Variance of one material's coefficients per unit of ``P`` (``1 / n_columns`` for a
        trained basis, 1 when the basis does not say).
    norm : float
        ``sum wV`` over the valid cells (``log_rmse``'s denominator per slice); 1 when unset.
    alias : (H, K, K) or None
        ``A_m``, the summed prior of the harmonics that fold onto each (module notes); a pair
        with row ``q`` measures harmonic ``m`` with noise ``noise_m + q^T A_m q``. None: no
        aliasing.
    """

    P: FloatArray
    harmonics: NDArray[np.intp]
    noise: FloatArray
    W: FloatArray
    scale: float = 1.0
    norm: float = 1.0
    alias: FloatArray | None = None

    def pair_noise(self, rows: FloatArray) -> FloatArray:
        """(H, n) noise variance of each pair's measurement of each harmonic."""
        Q = np.atleast_2d(rows)
        base = np.repeat(np.asarray(self.noise, dtype=float)[:, None], Q.shape[0], axis=1)
        if self.alias is None:
            return base
        return base + np.einsum("nk,hkl,nl->hn", Q, self.alias, Q)


def folded_onto(m: int, rotations: int) -> int | None:
    """The harmonic ``r = rotations`` uniform angles confuse harmonic ``m`` with, if resolved.

    ``min(m mod r, r - m mod r)``; None for the Nyquist fold (``2 m' = r``), which no resolved
    harmonic absorbs.
    """
    k = m % rotations
    fold = min(k, rotations - k)
    return fold if 2 * fold < rotations else None




def prior_model(basis: Basis, rotations: int = DEFAULT_ROTATIONS, eta: float = JOINT_ETA,
                lam: float = JOINT_LAM, slope: MetricSlope = "median",
                aliasing: bool = False, span_deg: float = DEFAULT_SPAN_DEG) -> PriorModel:
    """The prior the joint fit would use for a scan of ``rotations`` uniform stage angles.

    ``slope`` chooses how :func:`metric_gram` weighs the rows (``"spread"`` or ``"median"``);
    ``aliasing`` whether the harmonics the scan cannot resolve count as noise on the ones they
    fold onto (module notes). ``span_deg`` is the arc the angles cover (180 or 360): over half
    a turn, ``r`` angles see harmonic ``m = 2 j`` as a full turn's ``r`` angles see harmonic
    ``j`` (``2 j alpha_k = j (2 pi k / r)``), so even ``m`` is resolved for ``j < r / 2``; the
    odd harmonics, which the shipped priors do not hold, are left out.
    """
    if rotations < 1:
        raise DesignError(f"a scan needs at least one stage angle, got {rotations}")
    if not eta > 0 or lam < 0:
        raise DesignError(f"eta must be > 0 and lam >= 0, got eta={eta}, lam={lam}")
    try:
        per = span_periods(span_deg)
    except SamplesError as exc:
        raise DesignError(str(exc)) from None
    P = joint_prior(basis, lam / eta)
    ms = np.array([m for m in range(P.shape[0])
                   if m % per == 0 and 2 * (m // per) < rotations and np.any(P[m])],
                  dtype=np.intp)
    noise = np.where(ms == 0, eta / rotations, 2.0 * eta / rotations)
    cols = float(basis.provenance.get("n_columns", 0) or 0)
    norm = float(geo.volume_weight()[geo.valid_mask()].sum())
    alias = None
    if aliasing:
        alias = np.zeros((ms.size, basis.K, basis.K))
        where = {int(m): i for i, m in enumerate(ms)}
        for m in range(0, P.shape[0], per):
            fold = folded_onto(m // per, rotations)
            if 2 * (m // per) >= rotations and fold is not None and fold * per in where:
                alias[where[fold * per]] += P[m]
    return PriorModel(np.array(P[ms]), ms, noise, metric_gram(basis, slope),
                      scale=1.0 / cols if cols > 0 else 1.0, norm=norm, alias=alias)


def expected_error(model: PriorModel, rows: ArrayLike) -> float:
    """Expected squared metric error ``sum_m tr(W Sigma_m)`` after reading ``rows`` (Q rows).

    Parameters
    ----------
    model : PriorModel
    rows : (n, K) basis rows of the pairs

    Returns
    -------
    float
        In the metric's units squared (an expected ``log_rmse^2`` up to the volume
        normalisation), over the harmonics the scan resolves.
    """
    Q = np.atleast_2d(np.asarray(rows, dtype=float))
    total = 0.0
    for P, s in zip(model.P, model.pair_noise(Q), strict=True):
        Sig = _posterior(P, Q, s)
        total += float(np.sum(model.W * Sig))
    return total


def design_expected_log_rmse(model: PriorModel, rows: ArrayLike) -> float:
    """A design's expected ``log_rmse``: the joint fit's, after reading ``rows``, under the
    prior ``model`` (module notes).

    Not :attr:`gonio.brdf.reconstruction.posterior.ScanPosterior.expected_log_rmse`, the same
    expectation for one scan's readings under the prior scaled to its material.

    ``sqrt(scale * expected_error(model, rows) / norm)``: in ``log_rmse`` units for a model
    from :func:`prior_model` of a trained basis. It counts only what the readings leave
    undetermined inside the basis, so it is below the error on a real material (compare
    designs with it; ``gonio.brdf.design.heldout`` measures the whole error).

    Parameters
    ----------
    model : PriorModel
    rows : (n, K) basis rows of the pairs
    """
    return float(np.sqrt(model.scale * expected_error(model, rows) / model.norm))


def _posterior(P: FloatArray, Q: FloatArray, s: float | FloatArray) -> FloatArray:
    """``P - P Q^T (Q P Q^T + diag(s))^-1 Q P`` (one harmonic's posterior covariance).

    ``s``: the noise variance of every row, or (n,) one per row.
    """
    A = Q @ P
    G = A @ Q.T + np.diag(np.broadcast_to(np.asarray(s, dtype=float), (Q.shape[0],)))
    return np.asarray(P - A.T @ np.linalg.solve(G, A))


def greedy_rows(
    model: PriorModel, Q: ArrayLike, candidates: ArrayLike, n: int,
    accept: Callable[[NDArray[np.intp]], bool] | None = None, tries: int = 64,
    first: int = 0,
) -> NDArray[np.intp]:
    """Pick ``n`` of ``candidates`` (flat rows of ``Q``) greedily by expected-error reduction.

    Parameters
    ----------
    model : PriorModel
    Q : (N_rows, K) the basis rows
    candidates : (N,) int, flat rows allowed
    n : int, 1 <= n <= N
    accept : callable, optional
        ``accept(rows)`` says whether the chosen flat rows so far plus one more can be used
        together (e.g. mounted); each step takes the best candidate it accepts.
    tries : int
        Candidates tried per step before giving up.
    first : int
        Rank of the first pair among the (accepted) single-pair gains: 0 takes the best, a
        larger value starts the greedy elsewhere (different candidate designs).

    Returns
    -------
    (n,) int, the chosen flat rows in the order chosen.

    Raises
    ------
    FeasibilityError
        When ``accept`` refuses the ``tries`` best candidates of a step.
    """
    cand = np.asarray(candidates, dtype=np.intp)
    if not 1 <= n <= cand.size:
        raise DesignError(f"cannot choose {n} pairs from {cand.size} feasible cells")
    if not 0 <= first < cand.size:
        raise DesignError(f"the first pair's rank must be in 0..{cand.size - 1}, got {first}")
    Qc = np.asarray(Q, dtype=float)[cand]  # (N, K)
    noise = model.pair_noise(Qc)  # (H, N)
    Sig = [np.array(P) for P in model.P]
    chosen: list[int] = []
    for _ in range(n):
        gain = np.zeros(cand.size)
        for S, s in zip(Sig, noise, strict=True):
            A = S @ Qc.T  # (K, N): Sigma q for every candidate
            gain += np.sum((model.W @ A) * A, axis=0) / (np.sum(Qc.T * A, axis=0) + s)
        gain[chosen] = -np.inf  # a pair measured twice is a repeat, not a new pair
        skip = first if not chosen else 0
        if accept is None:
            k = int(np.argmax(gain)) if skip == 0 else int(np.argsort(-gain)[skip])
        else:
            order = np.argsort(-gain)[: min(tries + skip, cand.size - len(chosen))]
            ok = [int(j) for j in order if accept(cand[np.asarray([*chosen, int(j)])])][skip:]
            if not ok:
                raise FeasibilityError(
                    f"no mountable cell for pair {len(chosen) + 1} of {n} among the {tries} "
                    "best",
                    "lower {min_device_distance_deg} or ask for fewer pairs",
                )
            k = ok[0]
        chosen.append(k)
        q = Qc[k]
        for i, (S, s) in enumerate(zip(Sig, noise, strict=True)):
            a = S @ q
            Sig[i] = S - np.outer(a, a) / (q @ a + s[k])
    return cand[np.asarray(chosen, dtype=np.intp)]


def posterior_design(
    basis: Basis,
    n: int,
    constraints: RigConstraints,
    *,
    rotations: int = DEFAULT_ROTATIONS,
    eta: float = JOINT_ETA,
    lam: float = JOINT_LAM,
    seed: int = 0,
    time_limit_s: float | None = None,
    slope: MetricSlope = "median",
    aliasing: bool = False,
    span_deg: float = DEFAULT_SPAN_DEG,
    colour: ColourTargets | None = None,
    cell_weight: ArrayLike | None = None,
    cell_mix: float = 0.0,
) -> PairDesign:
    """``n`` pairs that minimise the joint fit's expected metric error (module notes).

    Parameters
    ----------
    basis : Basis
        With a ``ph_prior`` for anisotropic priors (an isotropic ``P_0 = I`` otherwise).
    n : int
        Number of pairs.
    constraints : RigConstraints
        Candidates are the feasible cells (:func:`gonio.brdf.design.constraints.candidate_rows`);
        lab azimuths come from :func:`gonio.brdf.design.placement.place_pairs`.
    rotations : int
        Uniform stage angles the scan will use (which harmonics it resolves).
    span_deg : {180, 360}
        The arc those angles cover (:data:`~gonio.brdf.reconstruction.samples.DEFAULT_SPAN_DEG`).
    eta, lam : float
        The joint fit's settings (reading noise and specular condition).
    seed : int, >= 0
        The rank of the first pair is ``seed`` modulo :data:`FIRST_RANKS` (``first`` of
        :func:`greedy_rows`; 0: the best), so consecutive seeds give different candidate
        designs; also the seed of the placement's shuffled orders.
    time_limit_s : float, optional
        Give up (:class:`~gonio.brdf.design.errors.DesignTimeout`) when the mount checks of
        the choice have used this many seconds of the calling thread's CPU time (CPU, not
        wall time, so that a loaded machine does not change the design; without a
        device-distance limit the choice checks no mounts and is quick).
    slope : {"spread", "median"}
        How the metric weighs the rows (:func:`metric_gram`).
    aliasing : bool
        Count the harmonics ``rotations`` cannot resolve as noise (module notes).
        The defaults (median slope, no aliasing) are the design as shipped: the two
        corrections did not lower the error on the benchmark (``docs/science.md`` 7.2.1).
        (The shipped design also mixes in the renderings' weighting, ``cell_mix=0.5``,
        which :func:`gonio.brdf.design.pairs.design_pairs` adds; here it is asked for.)
    colour : ColourTargets, optional
        Geometries a colour lab will read (:mod:`gonio.brdf.design.colourtargets`): the ones
        near the specular direction become pairs of their own (the first of the design), and
        the other pairs minimise the table's expected error plus ``colour.weight`` times the
        targets'. None (the default): the table's expected error alone.
    cell_weight : (18, 18, 36) array_like, optional
        Another weighting of the grid's cells (:func:`cell_gram`), e.g. the pixel counts of
        the standard renderings (:func:`gonio.brdf.pictures.appearance.render_importance`).
    cell_mix : float in [0, 1]
        The pairs minimise ``(1 - cell_mix)`` times the table's expected error plus
        ``cell_mix`` times the expected error weighted by ``cell_weight``, the latter scaled so
        that under the prior both count alike (``docs/science.md`` 7.2.2). 0 (the default):
        the table's expected error alone. ``expected_log_rmse`` of the result stays the
        table's.

    Returns
    -------
    PairDesign
        ``name="optimized"``, ``objective="posterior"``; ``kappa`` is the condition number of
        its rows, for comparison, ``expected_log_rmse`` the objective's own value
        (:func:`design_expected_log_rmse`), ``greedy`` what the choice did.

    Raises
    ------
    DesignError
        For ``n < 1``, more pairs than feasible cells, bad ``rotations`` / ``eta`` / ``lam``
        / ``slope``, or fewer pairs than ``colour`` needs for its direct pairs, a
        ``cell_mix`` outside [0, 1] or without a ``cell_weight``, or a bad ``cell_weight``.
    FeasibilityError
        When no cell is feasible or the chosen pairs cannot be mounted under ``constraints``.
    DesignTimeout
        When the choice runs past ``time_limit_s``.
    """
    if n < 1:
        raise DesignError(f"the number of pairs must be at least 1, got {n}")
    t0, cpu0 = time.perf_counter(), time.thread_time()
    model = prior_model(basis, rotations, eta, lam, slope, aliasing, span_deg)
    fixed: FloatArray = np.zeros((0, 3))
    choice = model
    if colour is not None and cell_mix > 0:
        # The mix would scale the renderings' term against a W that already holds the colour
        # term, inflating it by the colour weight: refuse rather than design on a wrong scale.
        raise DesignError("a colour design cannot also mix in a cell weighting (cell_mix > 0): "
                          "use one or the other")
    if colour is not None:
        fixed, choice = _colour_choice(basis, model, colour, n)
    if not 0.0 <= cell_mix <= 1.0:
        raise DesignError(f"cell_mix must be in [0, 1], got {cell_mix}")
    if cell_mix > 0:
        if cell_weight is None:
            raise DesignError("cell_mix > 0 needs a cell_weight map to mix in")
        choice = replace(choice, W=_mixed_gram(choice, cell_gram(basis, cell_weight, slope),
                                               cell_mix))
    accept = None
    checks = 0
    if constraints.min_device_distance_deg > 0:
        # Devices can collide: keep only choices that still mount (a quick placement check),
        # with the direct colour pairs, if any.
        def accept(rows: NDArray[np.intp]) -> bool:
            nonlocal checks
            if time_limit_s is not None and time.thread_time() - cpu0 > time_limit_s:
                raise DesignTimeout(
                    f"the expected-error choice did not finish within {time_limit_s:g} s of "
                    f"CPU time (at pair {rows.size} of {n}, {checks} mount checks)")
            checks += 1
            try:
                place_pairs(np.concatenate([fixed, rows_to_cells(rows)]), constraints,
                            ph_step_deg=1.0, orderings=4, seed=seed)
            except FeasibilityError:
                return False
            return True

    cand = candidate_rows(constraints, basis.valid)
    if seed < 0:
        raise DesignError(f"the seed must be at least 0, got {seed}")
    n_free = n - fixed.shape[0]
    # Any seed is valid; only the best few first pairs are worth starting from.
    first = seed % min(cand.size, FIRST_RANKS) if cand.size else 0
    rows = (greedy_rows(choice, basis.Q, cand, n_free, accept, first=first) if n_free
            else np.zeros(0, dtype=np.intp))
    cells = np.concatenate([fixed, rows_to_cells(rows)])
    placement = place_pairs(cells, constraints, ph_step_deg=1.0, seed=seed)
    q = np.asarray(basis.Q[rows])
    if fixed.shape[0]:
        q = np.concatenate([basis.rows_at(fixed[:, 0], fixed[:, 1], fixed[:, 2]), q])
    design = PairDesign.independent("optimized", placement, condition_number(q))
    stats = GreedyStats(candidates=int(cand.size), evaluations=int(n_free * cand.size),
                        mount_checks=checks, first=int(first),
                        seconds=time.perf_counter() - t0)
    return replace(design, objective="posterior",
                   expected_log_rmse=design_expected_log_rmse(model, q),
                   rotations=int(rotations), span_deg=float(span_deg), greedy=stats,
                   colour_pairs=int(fixed.shape[0]), cell_mix=float(cell_mix))


def _mixed_gram(model: PriorModel, Wc: FloatArray, mix: float) -> FloatArray:
    """``(1 - mix) W + mix ratio Wc``, ``ratio`` making both weigh the prior alike."""
    return np.asarray((1.0 - mix) * model.W + mix * _prior_ratio(model, Wc) * Wc)


def _prior_ratio(model: PriorModel, Wc: FloatArray) -> float:
    """How much ``Wc`` ((m, m)) must be scaled to weigh the prior as much as ``model.W`` does."""
    prior = model.P.sum(axis=0)
    return float(np.sum(model.W * prior)) / max(float(np.sum(Wc * prior)), 1e-300)


def _colour_choice(basis: Basis, model: PriorModel, colour: ColourTargets, n: int
                   ) -> tuple[FloatArray, PriorModel]:
    """The direct pairs' cells ((k, 3) radians) and the model the other pairs are chosen by:
    the prior after reading the direct pairs, the metric plus the weighted target term."""
    cells, _ph = colour.cells()
    direct = colour.direct()
    k = int(direct.sum())
    if k > n:
        raise DesignError(
            f"the colour geometries within {colour.direct_within_deg:g} deg of the specular "
            f"direction need {k} pairs of their own, but the design has {n}; ask for at least "
            f"{k} pairs or lower direct_within_deg")
    q_all = basis.rows_at(cells[:, 0], cells[:, 1], cells[:, 2])
    fixed = cells[direct]
    P = model.P
    if k:
        q = q_all[direct]
        P = np.stack([_posterior(Pm, q, s) for Pm, s in zip(model.P, model.pair_noise(q),
                                                                 strict=True)])
    W = model.W
    if colour.weight > 0:
        Wc = colour_gram(q_all)
        # Scaled so that, under the prior, weight 1 makes the targets count as much as the
        # whole table.
        W = W + colour.weight * _prior_ratio(model, Wc) * Wc
    return fixed, replace(model, P=P, W=W)

