"""A parametric tilt fitted before the joint fit (issue 25; docs/science.md 7.4).

A specimen whose every facet leans one way (a renderer's constant normal map, a blazed or
machined surface) has no twofold symmetry, and its lobe moves in ``th_h`` with the lean: the
linear-Gaussian prior of the joint fit cannot place such a lobe (science.md 7.4, "What does not
move the metals"). Here the lean is a parameter. The model is

``f(wi, wo) = g(R wi, R wo) * c(wo)``, ``c = (R wo)_z / wo_z * S_t(wo)``,

where ``R`` turns the leaning normal ``n = (sin t cos b, sin t sin b, cos t)`` (tilt ``t``
towards specimen azimuth ``b``) onto ``+z`` by the shortest rotation, and ``g`` is an ordinary
BRDF that the default (twofold-symmetric) basis can hold. The factor ``c`` is
what a normal map does to a BRDF quoted without the cosine: the nested BSDF is evaluated in
the leaning frame and its cosine-weighted value is ``g cos`` of the outgoing direction in that
frame, while the BRDF is that value over the geometric cosine; a renderer also dims grazing
``wo`` by a shadowing term (:func:`tilt_factor`; mitsuba 3's ``normalmap``, checked against
it: docs/science.md 7.4). It is zero where either direction is below the leaning horizon.

For each candidate ``(t, b)`` every reading's directions are mapped through ``R``, divided by
the factor and scored by the joint fit's **leave-one-pair-out** error in log units on the
readings themselves (each physical pair's readings at every stage angle predicted from all
other pairs' readings). Not the marginal likelihood: the candidates see different data (the
factor rescales the readings, and readings the lean puts below its horizon leave the fit), so
their evidences are not comparable, while the held-out error of the original readings is, and
it is what the result is judged by. ``t = 0`` is always a candidate, so a specimen without a
lean keeps the plain fit when nothing is gained. The search is a coarse grid, then a finer one
around its best.

Whether the lean found should replace the fit a scan gets without it (the reference: the
asymmetric basis' joint fit for a scan its test calls asymmetric) is a separate question, the
selection rule (:func:`tilt_decision`): the pooled held-out error cannot answer it, since a
misplaced lean can win it on the strength of a few pairs, so the rule counts the pairs whose
held-out error the lean lowers against the reference's (computed alike, :func:`holdout_errors`
at no lean with the reference basis) and accepts at least :data:`ACCEPT_PAIR_SHARE` of them.
The product does not call it: run once on two fresh sets it let through losses of 0.06 and
0.20 and refused good leans, and no threshold on the vote separates them there
(docs/science.md 7.4).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.linalg
from numpy.typing import ArrayLike, NDArray

from gonio.brdf.models.analytic import facet_rotation
from gonio.brdf.reconstruction.basis import Basis, BasisError, inverse_remap, remap
from gonio.brdf.reconstruction.errors import ReconstructionError
from gonio.brdf.reconstruction.joint import JOINT_ETA, JOINT_LAM, joint_prior
from gonio.brdf.reconstruction.reconstruct import Reconstruction, reconstruct
from gonio.brdf.reconstruction.samples import pair_directions
from gonio.brdf.tables import geometry as geo
from gonio.brdf.tables import interpolation as interp
from gonio.brdf.tables.table import VALID_MASK, BRDFTable

FloatArray = NDArray[np.float64]

#: Coarse candidate tilts (deg); 0 keeps the plain fit in the running.
COARSE_TILTS_DEG: tuple[float, ...] = (0.0, 5.0, 10.0, 15.0, 20.0, 25.0, 30.0)
#: Coarse candidate azimuths (deg), every 30.
COARSE_AZIMUTHS_DEG: tuple[float, ...] = tuple(float(a) for a in range(0, 360, 30))
#: Half-widths (deg) of the finer search around the coarse best: tilt, azimuth.
REFINE_STEPS_DEG: tuple[float, float] = (2.5, 10.0)
#: Readings whose mapped directions are this close to the leaning horizon (cosine) leave the
#: fit: the basis holds nothing there.
HORIZON_COS = 0.02
#: The selection rule (docs/science.md 7.4): the tilt fit is accepted over the reference fit
#: (the one a scan would get without it) only when its leave-one-pair-out error is lower on at
#: least this share of the pairs. Chosen on the choice set, where the tilt fit's losers lower
#: it on 3 and 6 of 10 pairs and its winners on 8 or 9: 0.7 sits in that gap. On the fresh
#: sets the losers' votes (5-8) overlap the winners' (5-9): the gap did not hold.
ACCEPT_PAIR_SHARE = 0.7
#: Fewer pairs than this cannot show a majority of folds: the tilt fit is never accepted.
ACCEPT_MIN_PAIRS = 5


def tilt_factor(R: FloatArray, wo: ArrayLike, terminator: bool = True) -> FloatArray:
    """The normal map's factor on ``g`` (module notes), 0 below either horizon.

    ``(R wo)_z / wo_z`` (the leaning frame's cosine over the geometric one) times the
    shadowing term a renderer applies to a leaning shading normal against the bump terminator
    (Estevez et al. 2019, as mitsuba 3's ``normalmap`` applies it by default):
    ``2 / (1 + sqrt(1 + a2 tan^2 theta_o))`` with ``a2 = min(tan^2 t / 8, 1)``, ``theta_o`` the
    geometric angle of ``wo`` and ``t`` the lean. Without it the model is 10x too bright at
    grazing ``wo`` (docs/science.md 7.4).

    Parameters
    ----------
    R : (3, 3) from :func:`facet_rotation`
    wo : (..., 3) unit vectors, specimen frame
    terminator : bool
        Include the shadowing term (default); without it, the bare normal map of
        :class:`gonio.brdf.models.analytic.Tilted` with ``masking="none"``.

    Returns
    -------
    (...,) float
    """
    o = np.asarray(wo, dtype=float)
    ro = o @ R.T
    ct = float(np.clip(R[2, 2], -1.0, 1.0))  # cos of the lean: R sends n to z about a level axis
    a2 = min((1.0 - ct * ct) / max(ct * ct, 1e-12) / 8.0, 1.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        c = ro[..., 2] / o[..., 2]
        tan2 = (1.0 - o[..., 2] ** 2) / o[..., 2] ** 2
        shadow = 2.0 / (1.0 + np.sqrt(1.0 + a2 * tan2)) if terminator else 1.0
    return np.where((o[..., 2] > 0) & (ro[..., 2] > 0), c * shadow, 0.0)


@dataclass(frozen=True)
class MappedReadings:
    """Readings seen in the leaning frame of one candidate (each reading its own cell).

    Attributes
    ----------
    cells : (N, 3) radians, ``(th, td, pd)`` of the mapped kept readings
    ph : (N,) radians, their mapped ``ph``
    values : (N, C) 1/sr, the readings divided by the factor
    factor : (N,) the factor of each kept reading
    keep : (n, r) bool, which readings are kept (above the leaning horizon)
    cos_i : (n, r) specimen-frame cosine of each reading's light
    """

    cells: FloatArray
    ph: FloatArray
    values: FloatArray
    factor: FloatArray
    keep: NDArray[np.bool_]
    cos_i: FloatArray


def map_readings(cells: ArrayLike, ph_lab: ArrayLike, stage_angles: ArrayLike,
                 values: ArrayLike, tilt: float, azimuth: float) -> MappedReadings:
    """Every reading's directions through :func:`facet_rotation` and its value over the factor.

    Parameters
    ----------
    cells : (n, 3) radians; ph_lab : (n,) radians; stage_angles : (r,) radians
        As for :func:`gonio.brdf.reconstruction.reconstruct.reconstruct`.
    values : (n, r, C) 1/sr
    tilt, azimuth : float, radians, the candidate lean in the specimen frame

    Returns
    -------
    MappedReadings
    """
    vals = np.asarray(values, dtype=float)
    alpha = np.asarray(stage_angles, dtype=float)
    wi_lab, wo_lab = pair_directions(cells, ph_lab)
    wi = geo.lab_to_specimen(wi_lab[:, None, :], alpha[None, :])  # (n, r, 3)
    wo = geo.lab_to_specimen(wo_lab[:, None, :], alpha[None, :])
    R = facet_rotation(tilt, azimuth)
    ri, ro = wi @ R.T, wo @ R.T
    keep = (ri[..., 2] > HORIZON_COS) & (ro[..., 2] > HORIZON_COS)
    th, ph, td, pd = geo.directions_to_half_diff(ri[keep], ro[keep])
    factor = tilt_factor(R, wo[keep])
    return MappedReadings(np.stack([th, td, pd], axis=1), ph,
                          vals[keep] / factor[:, None], factor, keep, wi[..., 2])


def _log_err(pred: FloatArray, vals: FloatArray, cos_i: FloatArray) -> FloatArray:
    """Per-reading log error as the self-estimate measures it (cosine-weighted log1p)."""
    c = cos_i[..., None]
    return np.log1p(np.maximum(pred, 0.0) * c) - np.log1p(vals * c)


def holdout_error(basis: Basis, cells: ArrayLike, ph_lab: ArrayLike, stage_angles: ArrayLike,
                  values: ArrayLike, tilt: float, azimuth: float, *,
                  eta: float = JOINT_ETA, lam: float = JOINT_LAM,
                  prior: FloatArray | None = None) -> float:
    """Leave-one-pair-out RMS log error of the readings under one candidate lean.

    The root mean square of :func:`holdout_errors` (module notes; parameters as there).

    Returns
    -------
    float
        RMS over readings and channels of the cosine-weighted log error (natural log units);
        inf when the candidate cannot be fitted.
    """
    return _pooled(holdout_errors(basis, cells, ph_lab, stage_angles, values, tilt, azimuth,
                                  eta=eta, lam=lam, prior=prior))


def _pooled(errors: FloatArray | None) -> float:
    """RMS of :func:`holdout_errors`' per-reading errors; inf for a candidate not fitted."""
    return float(np.sqrt(np.mean(errors**2))) if errors is not None else float("inf")


@dataclass(frozen=True)
class MappedFit:
    """The joint fit of one lean's mapped readings (:func:`mapped_joint_fit`), in the basis'
    remapped units: ``held`` each reading predicted without its pair, ``fitted`` the posterior
    mean at the readings themselves, both (N, C) over the readings kept; ``mu``, ``fmed``,
    ``w`` the (N, 1) terms that take them back to values (:func:`inverse_remap` of ``x + mu``)."""

    held: FloatArray
    fitted: FloatArray
    mu: FloatArray
    fmed: FloatArray
    w: FloatArray


def mapped_joint_fit(basis: Basis, m: MappedReadings, shape: tuple[int, int], eta: float,
                     prior: FloatArray) -> MappedFit | None:
    """The joint fit (learnt prior ``prior``, math.md 6; noise ratio ``eta``) of readings
    mapped through a lean (:func:`map_readings`), with each pair's readings also predicted
    from all the other pairs' (``shape`` = (n pairs, r angles) of the scan). None when the
    mapped cells fall outside the basis or the system is not positive definite."""
    n, r = shape
    pair_of = np.broadcast_to(np.arange(n)[:, None], (n, r))[m.keep]
    try:
        rows, weights = basis.neighbours(*m.cells.T)
    except BasisError:
        return None
    Qt = np.einsum("nj,njk->nk", weights, basis.Q[rows])
    fmed = (weights * basis.f_med[rows]).sum(axis=1)[:, None]
    mu = (weights * basis.mu[rows]).sum(axis=1)[:, None]
    ci, co = geo.cell_cosines(*m.cells.T)
    w = np.maximum(ci * co, basis.eps)[:, None]
    Y = remap(m.values, fmed, w, basis.eps) - mu  # (N, C)
    harm = np.arange(prior.shape[0], dtype=float)
    A = np.matmul(np.matmul(Qt[None], prior), Qt.T[None])  # (M, N, N)
    Z = np.exp(-1j * m.ph[:, None] * harm[None, :])  # (N, M)
    G = np.einsum("am,mab,bm->ab", Z, A, np.conj(Z)).real
    G[np.diag_indices_from(G)] += eta
    try:
        cho = scipy.linalg.cho_factor(G, lower=True)
    except np.linalg.LinAlgError:
        return None
    beta = scipy.linalg.cho_solve(cho, Y)
    Ginv = scipy.linalg.cho_solve(cho, np.eye(G.shape[0]))
    held = np.empty_like(Y)
    for q in range(n):
        idx = np.flatnonzero(pair_of == q)
        if idx.size:
            held[idx] = Y[idx] - np.linalg.solve(Ginv[np.ix_(idx, idx)], beta[idx])
    return MappedFit(held, Y - eta * beta, mu, fmed, w)


def holdout_errors(basis: Basis, cells: ArrayLike, ph_lab: ArrayLike, stage_angles: ArrayLike,
                   values: ArrayLike, tilt: float, azimuth: float, *,
                   eta: float = JOINT_ETA, lam: float = JOINT_LAM,
                   prior: FloatArray | None = None) -> FloatArray | None:
    """Each reading's leave-one-pair-out log error under one candidate lean.

    Each pair's readings (every stage angle) are predicted by the joint fit (learnt prior,
    math.md 6) of all other pairs' mapped readings, times the factor; readings the lean puts
    below its horizon are predicted 0 (what a normal map gives there).

    Parameters
    ----------
    basis : Basis
    cells, ph_lab, stage_angles, values
        The scan, as for :func:`map_readings`.
    tilt, azimuth : float, radians
    eta, lam : float
        The joint fit's noise-to-prior ratio and ``th = 0`` condition.
    prior : (M, K, K), optional
        ``joint_prior(basis, lam / eta)``, passed in to share it across candidates.

    Returns
    -------
    (n, r, C) float or None
        The cosine-weighted log error of every reading predicted without its pair (natural
        log units); None when the candidate cannot be fitted.
    """
    vals = np.asarray(values, dtype=float)
    m = map_readings(cells, ph_lab, stage_angles, vals, tilt, azimuth)
    P = joint_prior(basis, lam / eta) if prior is None else prior
    fit = mapped_joint_fit(basis, m, vals.shape[:2], eta, P)
    if fit is None:
        return None
    pred = np.zeros_like(vals)
    held, mu, fmed, w = fit.held, fit.mu, fit.fmed, fit.w
    back = inverse_remap(np.minimum(held + mu, 300.0), fmed, w, basis.eps)
    pred[m.keep] = np.maximum(back, 0.0) * m.factor[:, None]
    return _log_err(pred, vals, m.cos_i)


def tilted_table(g: BRDFTable, tilt: float, azimuth: float, name: str = "tilt fit",
                 interpolation: interp.Interpolation = "log-pchip") -> BRDFTable:
    """The table on gonio's grid of ``g`` seen through the lean (module notes).

    Every valid cell's directions are mapped through :func:`facet_rotation`, ``g`` is looked up
    there and multiplied by the factor; 0 where the lean puts either direction below its
    horizon. The lookup is the pictures' monotone cubic in ``ln(f + eps)``
    (:mod:`gonio.brdf.tables.interpolation`, math.md 3): the mapped cells fall between the
    nodes, and a lobe's flanks cut by the multilinear lookup's straight lines cost the
    renderer's own table, seen through its true lean, 0.06-0.15 of log_rmse
    (docs/science.md 7.4).

    Parameters
    ----------
    g : BRDFTable, the untilted BRDF
    tilt, azimuth : float, radians
    interpolation : {"log-pchip", "multilinear"}

    Returns
    -------
    BRDFTable, float32, NaN at invalid cells
    """
    th, td, pd = geo.grid_angles()
    R = facet_rotation(tilt, azimuth)
    nodes, ok, eps = interp.table_nodes(g.values)
    valid = ok.astype(np.float64)
    out = np.full((g.n_channels, geo.N_PH, *VALID_MASK.shape), np.nan, dtype=np.float32)
    for k, ph in enumerate(geo.PH_GRID):
        wi, wo = geo.half_diff_to_directions(th[VALID_MASK], ph, td[VALID_MASK], pd[VALID_MASK])
        ri, ro = wi @ R.T, wo @ R.T
        up = (ri[:, 2] > 0) & (ro[:, 2] > 0)
        val = np.zeros((wi.shape[0], g.n_channels))
        if interpolation == "multilinear":
            val[up] = g.eval(ri[up], ro[up])
        else:
            mth, mph, mtd, mpd = geo.directions_to_half_diff(ri[up], ro[up])
            lg, weight = interp.log_pchip_lookup(nodes, valid, mth, mph, mtd, mpd)
            val[up] = np.where(weight[:, None] > 1e-12, np.exp(lg) - eps, 0.0)
        val *= tilt_factor(R, wo)[:, None]
        out[:, k][:, VALID_MASK] = np.nan_to_num(np.maximum(val, 0.0), nan=0.0).T
    return BRDFTable.trusted(out, g.channels, name, g.wavelengths_nm,
                             {"reconstruction": {"tilt_deg": round(float(np.rad2deg(tilt)), 3),
                                                 "tilt_azimuth_deg":
                                                     round(float(np.rad2deg(azimuth)), 3)}})


def pair_rms(errors: ArrayLike) -> FloatArray:
    """Per pair, the RMS of its readings' held-out log errors.

    Parameters
    ----------
    errors : (n, r, C) from :func:`holdout_errors`

    Returns
    -------
    (n,) float
    """
    e = np.asarray(errors, dtype=float)
    return np.asarray(np.sqrt(np.mean(e.reshape(e.shape[0], -1) ** 2, axis=1)), dtype=float)


def tilt_decision(tilt_errors: ArrayLike | None, reference_errors: ArrayLike | None,
                  tilt: float, share: float = ACCEPT_PAIR_SHARE,
                  min_pairs: int = ACCEPT_MIN_PAIRS) -> tuple[bool, int, str]:
    """Whether the tilt fit replaces the reference fit: the selection rule (module notes).

    The lean is accepted when it is not zero and the tilt fit's leave-one-pair-out error is
    lower than the reference's on at least ``share`` of the pairs (a fold-wise vote, not the
    pooled error: on the choice set a misplaced lean won the pooled error on the strength of
    three pairs and lost the other seven, docs/science.md 7.4).

    Parameters
    ----------
    tilt_errors, reference_errors : (n, r, C) from :func:`holdout_errors`, or None when that
        fit could not be scored
    tilt : float, radians, the lean found
    share : float in (0, 1]
    min_pairs : int, fewer pairs are never enough

    Returns
    -------
    (accepted, pairs improved, reason)
    """
    if tilt <= 0:
        return False, 0, "no lean found (tilt 0)"
    if tilt_errors is None:
        return False, 0, "the lean's readings could not be fitted"
    if reference_errors is None:
        return False, 0, "the reference fit could not be scored"
    t, r = pair_rms(tilt_errors), pair_rms(reference_errors)
    if t.shape != r.shape:
        raise ReconstructionError(f"per-pair errors of different shapes: {t.shape}, {r.shape}")
    n = int(t.size)
    better = int(np.sum(t < r))
    if n < min_pairs:
        return False, better, f"{n} pairs are too few to judge a lean (at least {min_pairs})"
    need = int(np.ceil(share * n - 1e-9))
    verdict = better >= need
    return verdict, better, (f"the lean lowers the held-out error on {better} of {n} pairs "
                             f"({'at least' if verdict else 'fewer than'} {need} needed)")


def reconstruct_through(basis: Basis, cells: ArrayLike, ph_lab: ArrayLike,
                        stage_angles: ArrayLike, values: ArrayLike, tilt: float, azimuth: float,
                        *, channels: Sequence[str] = ("R", "G", "B"),
                        name: str = "tilt fit") -> tuple[Reconstruction, BRDFTable]:
    """The joint fit of the readings seen through one lean, and its table on gonio's grid.

    Parameters
    ----------
    basis : Basis
    cells, ph_lab, stage_angles, values
        The scan, as for :func:`map_readings`.
    tilt, azimuth : float, radians; a tilt of 0 gives exactly the plain joint fit of the
        scan as read
    channels : names of the ``C`` channels

    Returns
    -------
    (Reconstruction, BRDFTable)
        The fit of the untilted BRDF ``g`` and the table of ``g`` seen through the lean.
    """
    vals = np.asarray(values, dtype=float)
    if tilt > 0:
        m = map_readings(cells, ph_lab, stage_angles, vals, tilt, azimuth)
        g = reconstruct(basis, m.cells, m.ph, np.zeros(1), m.values[:, None, :],
                        channels=channels, name=f"{name} (untilted)")
        return g, tilted_table(g.table, tilt, azimuth, name)
    # No lean: exactly the plain joint fit of the scan as read.
    g = reconstruct(basis, cells, ph_lab, stage_angles, vals, channels=channels, name=name)
    return g, g.table


@dataclass(frozen=True)
class TiltFit:
    """The lean chosen and the reconstruction through it.

    Attributes
    ----------
    tilt, azimuth : float, radians (azimuth in the specimen frame)
    holdout_error : float, the chosen candidate's leave-one-pair-out log error
    plain_holdout_error : float, the same for ``t = 0`` (the plain fit)
    table : BRDFTable, the result on gonio's grid
    g : Reconstruction, the joint fit of the untilted BRDF
    candidates : (N, 3) float, every ``(tilt deg, azimuth deg, error)`` tried
    seconds : float, CPU-side wall time of the search and fit
    accepted : bool, the selection rule's verdict against the reference fit
        (:func:`tilt_decision`); False without a reference
    pairs_improved : int, pairs whose held-out error the lean lowers against the reference
    n_pairs : int
    decision : str, the rule's reason in words
    """

    tilt: float
    azimuth: float
    holdout_error: float
    plain_holdout_error: float
    table: BRDFTable
    g: Reconstruction
    candidates: FloatArray = field(repr=False)
    seconds: float = 0.0
    accepted: bool = False
    pairs_improved: int = 0
    n_pairs: int = 0
    decision: str = "not judged (no reference fit)"

    @property
    def settings(self) -> dict[str, Any]:
        """The fitted lean in degrees and the rule's decision, for a result's metrics."""
        return {"tilt_deg": round(float(np.rad2deg(self.tilt)), 3),
                "tilt_azimuth_deg": round(float(np.rad2deg(self.azimuth)) % 360.0, 3),
                "tilt_accepted": bool(self.accepted), "tilt_decision": self.decision}


def refine_around(score: Callable[[float, float], float],
                  tried: Mapping[tuple[float, float], float],
                  steps_deg: tuple[float, float] = REFINE_STEPS_DEG,
                  rounds: int = 2) -> tuple[float, float]:
    """The lean of least score after finer rounds around the best one tried so far.

    Each round scores the 3 x 3 leans at the steps around the best (tilts below 0 skipped),
    then halves the steps. A best lean of no tilt is kept as it is (there is no azimuth to
    refine).

    Parameters
    ----------
    score : scores a lean ``(t, b)`` in degrees and records it in ``tried`` (under the
        caller's own key for it)
    tried : the leans scored so far, ``(t, b)`` degrees -> score; read after every round
    steps_deg : the first round's steps of tilt and azimuth, degrees
    rounds : how many rounds

    Returns
    -------
    The best key of ``tried`` at the end.
    """
    best = min(tried, key=tried.__getitem__)
    if best[0] <= 0:
        return best
    dt, db = steps_deg
    for _ in range(rounds):
        t_c, b_c = best
        for t in (t_c - dt, t_c, t_c + dt):
            for b in (b_c - db, b_c, b_c + db):
                if t >= 0:
                    score(t, b)
        best = min(tried, key=tried.__getitem__)
        dt, db = dt / 2, db / 2
    return best


def fit_tilt(basis: Basis, cells: ArrayLike, ph_lab: ArrayLike, stage_angles: ArrayLike,
             values: ArrayLike, *, channels: Sequence[str] = ("R", "G", "B"),
             tilts_deg: Sequence[float] = COARSE_TILTS_DEG,
             azimuths_deg: Sequence[float] = COARSE_AZIMUTHS_DEG,
             refine: bool = True, name: str = "tilt fit",
             reference: Basis | None = None) -> TiltFit:
    """Choose the lean by held-out error, then reconstruct through it (module notes).

    Parameters
    ----------
    basis : Basis, a twofold-symmetric basis (the default)
    cells, ph_lab, stage_angles, values
        The scan, as for :func:`gonio.brdf.reconstruction.reconstruct.reconstruct`; the
        stage angles should cover the full turn (a lean is odd in the stage angle).
    channels : names of the ``C`` channels
    tilts_deg, azimuths_deg : the coarse grid; a tilt of 0 is always tried
    refine : search a finer grid (:data:`REFINE_STEPS_DEG`) around the coarse best
    reference : Basis, optional
        The basis of the fit the scan gets without the tilt (the asymmetric basis for a scan
        its test calls asymmetric): its plain joint fit's leave-one-pair-out errors, computed
        as the candidates' are, decide :attr:`TiltFit.accepted` (:func:`tilt_decision`).

    Returns
    -------
    TiltFit
    """
    t0 = time.perf_counter()
    vals = np.asarray(values, dtype=float)
    if vals.ndim != 3:
        raise ReconstructionError(f"values must be (n, r, C), got shape {vals.shape}")
    P = joint_prior(basis, JOINT_LAM / JOINT_ETA)
    tried: dict[tuple[float, float], float] = {}
    # Each candidate's per-reading errors, kept: the selection rule reads the best one's.
    errors: dict[tuple[float, float], FloatArray | None] = {}

    def score(t: float, b: float) -> float:
        key = (round(t, 6), round(b % 360.0, 6) if t > 0 else 0.0)
        if key not in tried:
            err = holdout_errors(basis, cells, ph_lab, stage_angles, vals,
                                 np.deg2rad(key[0]), np.deg2rad(key[1]), prior=P)
            errors[key], tried[key] = err, _pooled(err)
        return tried[key]

    score(0.0, 0.0)
    for t in tilts_deg:
        for b in (azimuths_deg if t > 0 else (0.0,)):
            score(float(t), float(b))
    best = (refine_around(score, tried) if refine
            else min(tried, key=tried.__getitem__))
    tilt, azimuth = np.deg2rad(best[0]), np.deg2rad(best[1])
    g, table = reconstruct_through(basis, cells, ph_lab, stage_angles, vals, tilt, azimuth,
                                   channels=channels, name=name)
    cand = np.array([(t, b, e) for (t, b), e in tried.items()], dtype=float)
    accepted, better, why, n_pairs = False, 0, "not judged (no reference fit)", vals.shape[0]
    if reference is not None:
        ref_errors = holdout_errors(reference, cells, ph_lab, stage_angles, vals, 0.0, 0.0)
        tilt_errors = errors[best] if best[0] > 0 else None
        accepted, better, why = tilt_decision(tilt_errors, ref_errors, float(tilt))
    return TiltFit(float(tilt), float(azimuth), tried[best], tried[(0.0, 0.0)], table, g,
                   cand, time.perf_counter() - t0, accepted, better, n_pairs, why)
