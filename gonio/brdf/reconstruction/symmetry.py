"""Does the specimen read the same turned by half a turn? A test on the readings themselves.

Half-turn scans (the default, science.md 7.4) are right only for specimens with twofold
symmetry: ``f(R(a) wi, R(a) wo) = f(R(a + pi) wi, R(a + pi) wo)`` for every pair. A scan that
reads each pair at opposite stage angles ``a`` and ``a + 180 deg`` sees that directly: for such
a specimen the two readings differ by noise alone. :func:`twofold_test` scales the differences
of their logarithms by the noise model and sums their squares, a chi-square statistic
(math.md 11):

``T_q = sum_k sum_c (ln y_q(a_k) - ln y_q(a_k + pi))^2 / s^2``,
``s^2 = 2 (relative^2 + (absolute / v)^2)``, ``v`` the mean of the two readings,

per pair ``q`` over its opposite angle pairs ``k`` and channels ``c``, and ``T = sum_q T_q``
overall. Under the noise model (:class:`~gonio.brdf.reconstruction.samples.NoiseModel`:
independent Gaussian relative and absolute noise per reading) and twofold symmetry, each term
is the square of a standard normal to first order in the noise, so ``T_q`` and ``T`` follow
chi-square distributions with as many degrees of freedom as terms. The verdict is "not
symmetric" when the upper tail probability falls below ``false_alarm``: a twofold-symmetric
specimen is called asymmetric with probability ``false_alarm`` overall (and per pair, each pair
taken alone; over ``n`` pairs some pair is flagged more often, up to ``n false_alarm``).

What it cannot know: errors outside the noise model (a stage that misses its angle on a steep
lobe flank, a tilted mount that wobbles once per turn, drift between the two readings) look
like asymmetry; such a rig needs a larger noise model or a smaller ``false_alarm``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import stats

from gonio.brdf.reconstruction.samples import NoiseModel

FloatArray = NDArray[np.float64]

#: Default probability of calling a twofold-symmetric specimen asymmetric (overall verdict).
DEFAULT_FALSE_ALARM = 0.01
#: Two stage angles are opposite when they differ by 180 deg within this (radians).
DEFAULT_TOLERANCE = float(np.deg2rad(0.5))
#: Readings whose log has a predicted standard deviation above this are left out: there the
#: absolute noise dominates, the log is far from Gaussian and the first-order scaling fails.
MAX_LOG_SD = 0.1


class SymmetryError(ValueError):
    """The readings cannot be tested (no opposite angles, bad shapes); says what to do."""


@dataclass(frozen=True)
class TwofoldTest:
    """Result of :func:`twofold_test`.

    Attributes
    ----------
    opposite : (m, 2) int array
        Indices into the stage angles of the opposite angle pairs used (``a``, ``a + 180``).
    statistic, dof, p_value : (n,) arrays
        Per pair: ``T_q``, its degrees of freedom (terms used; 0 when every reading of the
        pair was left out) and the chi-square upper tail probability (1 where ``dof`` is 0).
    symmetric : (n,) bool array
        Per pair: ``p_value >= false_alarm``.
    rms_log_difference : (n,) array
        Per pair, the root mean square of ``ln y(a) - ln y(a + pi)`` over its terms (the size
        of the asymmetry in log units; NaN where ``dof`` is 0).
    total_statistic, total_dof, total_p_value : float, int, float
        Overall: ``T``, its degrees of freedom and upper tail probability.
    overall_symmetric : bool
        ``total_p_value >= false_alarm``.
    false_alarm : float
        The level used.
    """

    opposite: NDArray[np.intp]
    statistic: FloatArray
    dof: NDArray[np.intp]
    p_value: FloatArray
    symmetric: NDArray[np.bool_]
    rms_log_difference: FloatArray
    total_statistic: float
    total_dof: int
    total_p_value: float
    overall_symmetric: bool
    false_alarm: float


def opposite_angles(stage_angles: ArrayLike,
                    tolerance: float = DEFAULT_TOLERANCE) -> NDArray[np.intp]:
    """Disjoint pairs of stage angles half a turn apart.

    Parameters
    ----------
    stage_angles : (r,) array_like, radians
    tolerance : float, radians
        Largest departure of the difference from ``pi``.

    Returns
    -------
    (m, 2) int array
        ``(i, j)`` with ``alpha[j] - alpha[i] = pi`` modulo ``2 pi`` within ``tolerance``; each
        angle appears in at most one pair, so the pairs' differences have independent noise.
    """
    a = np.mod(np.asarray(stage_angles, dtype=float).ravel(), 2 * np.pi)
    used = np.zeros(a.size, dtype=bool)
    out: list[tuple[int, int]] = []
    for i in np.argsort(a, kind="stable"):
        if used[i]:
            continue
        gap = np.abs(np.angle(np.exp(1j * (a - a[i] - np.pi))))
        gap[used] = np.inf
        gap[i] = np.inf
        j = int(np.argmin(gap))
        if gap[j] <= tolerance:
            used[i] = used[j] = True
            out.append((int(i), j))
    return np.asarray(out, dtype=np.intp).reshape(-1, 2)


def twofold_test(
    stage_angles: ArrayLike,
    values: ArrayLike,
    noise: NoiseModel,
    *,
    false_alarm: float = DEFAULT_FALSE_ALARM,
    tolerance: float = DEFAULT_TOLERANCE,
) -> TwofoldTest:
    """Test pair by pair and overall whether readings at opposite stage angles agree.

    Parameters
    ----------
    stage_angles : (r,) array_like, radians
        Must include at least one pair half a turn apart (e.g. 8 uniform angles over a full
        turn hold 4 such pairs).
    values : (n, r, C) array_like, 1/sr
        Readings of ``n`` pairs at the ``r`` stage angles in ``C`` channels (as
        :func:`~gonio.brdf.reconstruction.reconstruct.reconstruct` takes them).
    noise : NoiseModel
        The rig's noise (``relative`` and ``absolute``); the test's scale. Its seed is unused.
    false_alarm : float in (0, 1)
        Probability of calling a twofold-symmetric specimen asymmetric under ``noise``.
    tolerance : float, radians
        How far from 180 deg apart two angles may be and still count as opposite.

    Returns
    -------
    TwofoldTest

    Raises
    ------
    SymmetryError
        Shapes do not match, the noise model is zero, ``false_alarm`` is outside (0, 1), no
        two stage angles are opposite, or no reading is usable.
    """
    alpha = np.asarray(stage_angles, dtype=float).ravel()
    y = np.asarray(values, dtype=float)
    if y.ndim == 2:
        y = y[:, :, None]
    if y.ndim != 3 or y.shape[1] != alpha.size:
        raise SymmetryError(
            f"values have shape {np.shape(values)}, expected (pairs, {alpha.size} stage angles, "
            "channels); give one reading per pair, stage angle and channel"
        )
    if not 0.0 < false_alarm < 1.0:
        raise SymmetryError(f"false_alarm = {false_alarm} must lie strictly between 0 and 1")
    if noise.relative == 0 and noise.absolute == 0:
        raise SymmetryError(
            "the noise model is zero, so any difference would count as asymmetry; give the "
            "rig's noise (NoiseModel(relative=..., absolute=...))"
        )
    pairs = opposite_angles(alpha, tolerance)
    if pairs.shape[0] == 0:
        raise SymmetryError(
            f"no two of the {alpha.size} stage angles are 180 deg apart (within "
            f"{np.rad2deg(tolerance):.2g} deg); scan a full turn with an even number of "
            "uniform angles (e.g. 8 over 360 deg) to test twofold symmetry"
        )
    a, b = y[:, pairs[:, 0], :], y[:, pairs[:, 1], :]  # (n, m, C)
    with np.errstate(divide="ignore", invalid="ignore"):
        v = 0.5 * (a + b)
        var_log = noise.relative**2 + (noise.absolute / v) ** 2  # of one reading's log
        d = np.log(a) - np.log(b)
        use = (np.isfinite(d) & (a > 0) & (b > 0) & np.isfinite(var_log)
               & (var_log <= MAX_LOG_SD**2))
        z2 = np.where(use, d**2 / (2.0 * var_log), 0.0)
    if not use.any():
        raise SymmetryError(
            "no pair has usable readings at opposite angles (all zero, missing or dominated by "
            f"absolute noise, predicted log standard deviation above {MAX_LOG_SD}); the test "
            "needs readings well above the noise floor"
        )
    dof = use.sum(axis=(1, 2)).astype(np.intp)
    stat = z2.sum(axis=(1, 2))
    p = np.where(dof > 0, stats.chi2.sf(stat, np.maximum(dof, 1)), 1.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        rms = np.sqrt(np.where(use, d**2, 0.0).sum(axis=(1, 2)) / dof)
    rms = np.where(dof > 0, rms, np.nan)
    total = float(stat.sum())
    total_dof = int(dof.sum())
    total_p = float(stats.chi2.sf(total, total_dof))
    return TwofoldTest(
        opposite=pairs, statistic=stat, dof=dof, p_value=p, symmetric=p >= false_alarm,
        rms_log_difference=rms, total_statistic=total, total_dof=total_dof,
        total_p_value=total_p, overall_symmetric=total_p >= false_alarm,
        false_alarm=float(false_alarm),
    )
