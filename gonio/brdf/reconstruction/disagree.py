"""A round of readings placed where two fits disagree (issue 25; docs/science.md 7.4).

Two reconstructions of one scan (today's joint fit and the tilt fit of
:mod:`gonio.brdf.reconstruction.tilt`) can both explain the readings they were fitted on and
still differ elsewhere. Scores computed from those readings did not tell which one is right
(science.md 7.4), so this module reads the difference instead: both fits predict every pair at
candidate stage angles, the angles where the predictions differ most relative to the reading
noise are read, and the fit whose predictions of the new readings are closer (a noise-scaled
chi-square) is kept.

The noise is modelled in log units as the arc test models it: a relative part plus an absolute
part proportional to the pair's largest reading (so dim readings, whose shot noise is larger,
weigh less). A study: the product does not call it. Chosen on one set of specimens and run
once on two fresh ones, a round of 40 readings after a first pass of 80 kept the better fit on
half the specimens only, and lost to today's path (docs/science.md 7.4).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from gonio.brdf.reconstruction.errors import ReconstructionError
from gonio.brdf.reconstruction.samples import pair_directions
from gonio.brdf.tables import geometry as geo
from gonio.brdf.tables import interpolation as interp
from gonio.brdf.tables.table import BRDFTable

FloatArray = NDArray[np.float64]

#: Candidate stage angles of the round are every this many degrees over the full turn.
CANDIDATE_STEP_DEG = 5.0
#: Each angle of the round is at least this far (deg) from every angle read or chosen: two
#: readings a few degrees apart repeat most of what one says.
MIN_SEPARATION_DEG = 10.0
#: Relative noise of one reading (the bench's and the arc test's default).
RELATIVE_NOISE = 0.01
#: Absolute noise as a share of the pair's largest reading (as the arc test's).
ABSOLUTE_NOISE = 0.01


def predict_readings(table: BRDFTable, cells: ArrayLike, ph_lab: ArrayLike,
                     stage_angles: ArrayLike) -> FloatArray:
    """What ``table`` predicts each pair reads at each stage angle.

    The lookup is the pictures' monotone cubic in ``ln(f + eps)``
    (:mod:`gonio.brdf.tables.interpolation`): a lobe's flanks between the grid's nodes are
    where two fits differ, and straight lines would cut them.

    Parameters
    ----------
    table : BRDFTable
    cells : (n, 3) radians, ``(th, td, pd)`` of the pairs
    ph_lab : (n,) radians, the pairs' ``ph`` in the lab frame
    stage_angles : (r,) radians

    Returns
    -------
    (n, r, C) float, 1/sr; 0 where either direction is below the horizon
    """
    alpha = np.atleast_1d(np.asarray(stage_angles, dtype=float))
    wi_lab, wo_lab = pair_directions(cells, ph_lab)
    n = wi_lab.shape[0]
    wi = geo.lab_to_specimen(wi_lab[:, None, :], alpha[None, :]).reshape(-1, 3)
    wo = geo.lab_to_specimen(wo_lab[:, None, :], alpha[None, :]).reshape(-1, 3)
    v = np.asarray(table.values)
    nodes, ok, eps = interp.table_nodes(v)
    out = np.zeros((wi.shape[0], v.shape[0]))
    up = (wi[:, 2] > 0) & (wo[:, 2] > 0)
    th, ph, td, pd = geo.directions_to_half_diff(wi[up], wo[up])
    lg, weight = interp.log_pchip_lookup(nodes, ok.astype(np.float64), th, ph, td, pd)
    out[up] = np.where(weight[:, None] > 1e-12, np.maximum(np.exp(lg) - eps, 0.0), 0.0)
    return out.reshape(n, alpha.size, v.shape[0])


def log_noise_var(level: ArrayLike, peak: ArrayLike, relative: float = RELATIVE_NOISE,
                  absolute: float = ABSOLUTE_NOISE) -> FloatArray:
    """Variance of a reading's natural log under the noise model (module notes).

    ``relative**2 + (absolute * peak / level)**2``: a relative error ``relative`` plus an
    absolute one of ``absolute`` times the pair's largest reading.

    Parameters
    ----------
    level : (...,) array, the reading's level (1/sr or counts)
    peak : array broadcastable to ``level``, the pair's largest reading in the same unit
    relative, absolute : float

    Returns
    -------
    (...,) float; inf where ``level`` is not above 0
    """
    lv = np.asarray(level, dtype=float)
    pk = np.asarray(peak, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(lv > 0, absolute * pk / np.where(lv > 0, lv, 1.0), np.inf)
    return np.asarray(relative**2 + ratio**2, dtype=float)


def pair_peaks(values: ArrayLike) -> FloatArray:
    """Each pair's and channel's largest reading, the absolute noise's scale.

    Parameters
    ----------
    values : (n, r, C) readings

    Returns
    -------
    (n, 1, C) float, broadcastable against (n, r', C)
    """
    v = np.asarray(values, dtype=float)
    if v.ndim != 3:
        raise ReconstructionError(f"readings must be (n, r, C), got shape {v.shape}")
    return np.asarray(np.nanmax(np.where(np.isfinite(v), v, -np.inf), axis=1, keepdims=True)
                      .clip(min=0.0), dtype=float)


def disagreement(pred_a: ArrayLike, pred_b: ArrayLike, peak: ArrayLike,
                 relative: float = RELATIVE_NOISE,
                 absolute: float = ABSOLUTE_NOISE) -> FloatArray:
    """Per stage angle, how far two fits' predictions are apart in units of the noise.

    ``sum over pairs and channels of (ln a - ln b)**2 / var``, with ``var`` the
    :func:`log_noise_var` at the two predictions' mean; a pair where either prediction is 0
    counts as if at the absolute noise's level (so a lobe one fit puts below the other's
    horizon still counts, but no more than a reading at that level would).

    Parameters
    ----------
    pred_a, pred_b : (n, r, C) predictions (:func:`predict_readings`)
    peak : (n, 1, C) the pairs' largest readings (:func:`pair_peaks`)
    relative, absolute : float

    Returns
    -------
    (r,) float, 0 where the predictions agree
    """
    a = np.asarray(pred_a, dtype=float)
    b = np.asarray(pred_b, dtype=float)
    if a.shape != b.shape or a.ndim != 3:
        raise ReconstructionError(f"predictions of shapes {a.shape} and {b.shape}; both must "
                                  "be (n, r, C)")
    floor = absolute * np.asarray(peak, dtype=float) + 1e-30
    la, lb = np.log(np.maximum(a, floor)), np.log(np.maximum(b, floor))
    var = log_noise_var(np.maximum(0.5 * (a + b), floor), peak, relative, absolute)
    return np.asarray(np.sum((la - lb) ** 2 / var, axis=(0, 2)), dtype=float)


def chi_terms(pred: ArrayLike, readings: ArrayLike, peak: ArrayLike,
              relative: float = RELATIVE_NOISE, absolute: float = ABSOLUTE_NOISE) -> FloatArray:
    """Each reading's noise-scaled squared log residual against a fit's prediction.

    As :func:`disagreement` does for two predictions, between a fit's predictions and the
    readings (the variance at the reading's level); 0 for a reading that is not finite.

    Parameters
    ----------
    pred, readings : (n, r, C)
    peak : (n, 1, C), the pairs' largest readings of the pass before (:func:`pair_peaks`)
    relative, absolute : float

    Returns
    -------
    (n, r, C) float
    """
    p = np.asarray(pred, dtype=float)
    y = np.asarray(readings, dtype=float)
    if p.shape != y.shape:
        raise ReconstructionError(f"predictions {p.shape} and readings {y.shape} differ in shape")
    floor = absolute * np.asarray(peak, dtype=float) + 1e-30
    ok = np.isfinite(y)
    yy = np.where(ok, y, floor)
    res = np.log(np.maximum(p, floor)) - np.log(np.maximum(yy, floor))
    var = log_noise_var(np.maximum(yy, floor), peak, relative, absolute)
    return np.asarray(np.where(ok, res**2 / var, 0.0), dtype=float)


def chi_square(pred: ArrayLike, readings: ArrayLike, peak: ArrayLike,
               relative: float = RELATIVE_NOISE, absolute: float = ABSOLUTE_NOISE) -> float:
    """How well a fit predicted readings: the sum of :func:`chi_terms` (lower is better).

    Parameters
    ----------
    pred, readings : (n, r, C)
    peak : (n, 1, C), the pairs' largest readings of the pass before (:func:`pair_peaks`)
    relative, absolute : float

    Returns
    -------
    float
    """
    return float(np.sum(chi_terms(pred, readings, peak, relative, absolute)))


def pair_cosines(cells: ArrayLike, ph_lab: ArrayLike) -> FloatArray:
    """Each pair's light cosine (the same at every stage angle: the stage turns about ``z``).

    Parameters
    ----------
    cells : (n, 3) radians; ph_lab : (n,) radians

    Returns
    -------
    (n, 1, 1) float, broadcastable against (n, r, C)
    """
    wi, _ = pair_directions(cells, ph_lab)
    return np.asarray(wi[:, 2], dtype=float)[:, None, None]


def _metric_log(values: FloatArray, cos_i: ArrayLike) -> FloatArray:
    """``ln(1 + f cos_i)``: the cosine-weighted log of the self-estimate and log_rmse."""
    return np.asarray(np.log1p(np.maximum(values, 0.0) * np.asarray(cos_i, dtype=float)),
                      dtype=float)


def metric_disagreement(pred_a: ArrayLike, pred_b: ArrayLike, cos_i: ArrayLike) -> FloatArray:
    """Per stage angle, how far two fits' predictions are apart in the metric's own units.

    ``sum over pairs and channels of (ln(1 + a cos_i) - ln(1 + b cos_i))**2``: the
    cosine-weighted log the reconstruction is judged by (log_rmse, the self-estimate), so a dim
    reading far in ratio but near in that log weighs what it costs the result, not what the
    noise makes of it.

    Parameters
    ----------
    pred_a, pred_b : (n, r, C) predictions (:func:`predict_readings`)
    cos_i : (n, 1, 1) light cosines (:func:`pair_cosines`)

    Returns
    -------
    (r,) float
    """
    a = np.asarray(pred_a, dtype=float)
    b = np.asarray(pred_b, dtype=float)
    if a.shape != b.shape or a.ndim != 3:
        raise ReconstructionError(f"predictions of shapes {a.shape} and {b.shape}; both must "
                                  "be (n, r, C)")
    d = _metric_log(a, cos_i) - _metric_log(b, cos_i)
    return np.asarray(np.sum(d**2, axis=(0, 2)), dtype=float)


def metric_error(pred: ArrayLike, readings: ArrayLike, cos_i: ArrayLike) -> float:
    """RMS of a fit's prediction errors on readings in the metric's units
    (:func:`metric_disagreement`); readings that are not finite are left out.

    Parameters
    ----------
    pred, readings : (n, r, C)
    cos_i : (n, 1, 1) light cosines

    Returns
    -------
    float, natural log units, lower is better; nan with no finite reading
    """
    p = np.asarray(pred, dtype=float)
    y = np.asarray(readings, dtype=float)
    if p.shape != y.shape:
        raise ReconstructionError(f"predictions {p.shape} and readings {y.shape} differ in shape")
    ok = np.isfinite(y)
    if not ok.any():
        return float("nan")
    d = _metric_log(p, cos_i) - _metric_log(np.where(ok, y, 0.0), cos_i)
    return float(np.sqrt(np.mean(d[ok] ** 2)))


def _angular_gap(a: FloatArray, b: Sequence[float]) -> FloatArray:
    """Distance (deg, on the circle) of each of ``a`` to the nearest of ``b``; inf if none."""
    if len(b) == 0:
        return np.full(a.shape, np.inf)
    d = np.abs((a[:, None] - np.asarray(b, dtype=float)[None, :] + 180.0) % 360.0 - 180.0)
    return np.asarray(d.min(axis=1), dtype=float)


def candidate_angles(step_deg: float = CANDIDATE_STEP_DEG) -> FloatArray:
    """Candidate stage angles of the round: every ``step_deg`` over the full turn (deg)."""
    if not 0 < step_deg <= 180:
        raise ReconstructionError(f"candidate step {step_deg} deg must be in (0, 180]")
    return np.arange(0.0, 360.0 - 1e-9, step_deg)


def choose_angles(scores: ArrayLike, candidates_deg: ArrayLike, read_deg: Sequence[float],
                  count: int, min_separation_deg: float = MIN_SEPARATION_DEG) -> list[float]:
    """The round's stage angles: greedily the most disagreeing candidates, spaced apart.

    Each pick is the candidate of largest score at least ``min_separation_deg`` from every
    angle read and every one picked; among equal scores (two fits that agree everywhere) the
    one farthest from the angles read and picked, so an uninformative round spreads out.

    Parameters
    ----------
    scores : (m,) float, :func:`disagreement` at each candidate
    candidates_deg : (m,) degrees
    read_deg : the stage angles already read, degrees
    count : how many angles to choose
    min_separation_deg : float

    Returns
    -------
    list of float, degrees in [0, 360), in the order picked; fewer than ``count`` when no
    candidate is left far enough from the others
    """
    s = np.asarray(scores, dtype=float)
    c = np.asarray(candidates_deg, dtype=float) % 360.0
    if s.shape != c.shape:
        raise ReconstructionError(f"{s.size} scores for {c.size} candidate angles")
    if count < 0:
        raise ReconstructionError(f"cannot choose {count} angles")
    taken = [float(a) % 360.0 for a in read_deg]
    picked: list[float] = []
    for _ in range(count):
        gap = _angular_gap(c, taken + picked)
        free = gap >= min_separation_deg - 1e-9
        if not free.any():
            break
        best = max(np.flatnonzero(free), key=lambda k: (s[k], gap[k]))
        picked.append(float(c[best]))
    return picked
