"""``predicted_log_rmse``: the self-estimated error of a joint reconstruction (issue 9 item 5).

Two things make a reconstruction's ``log_rmse`` against the true BRDF large, and each has its
own witness in the scan:

* **what the readings leave undetermined** inside the basis: the joint fit's posterior
  variance, weighted as ``log_rmse`` weighs errors and scaled to the material by empirical
  Bayes (:attr:`gonio.brdf.reconstruction.posterior.ScanPosterior.expected_log_rmse`,
  ``expected``);
* **what the basis cannot represent**: invisible to the posterior. Two witnesses carry it:
  how far the fit had to go from the training library to pass through the readings (the
  squared Mahalanobis norm of the fitted readings under the prior,
  :attr:`~gonio.brdf.reconstruction.posterior.ScanPosterior.mahalanobis`), and how badly the
  fit to the *other* pairs predicts each pair (``cv_sample_error``, leave-one-pair-out
  relative error).

The two parts add as variances:

``predicted_log_rmse^2 = exp(a) expected^2 + exp(b) min(mahalanobis, M)^c min(cv, V)^d``

(:data:`LOG_RMSE_MODEL`, caps :data:`LOG_RMSE_CAPS`), fitted by least squares in
``ln(log_rmse)`` on held-out training materials (the synthetic panel of
:mod:`gonio.brdf.design.heldout` and half of the measured materials) read with the layouts the
product runs (pairs designed by the joint fit's expected error for a scan over half a turn, the
default; the same for a full turn; the MA68 and MA98 presets and condition-number designs over
either arc), and checked on materials never calibrated on (the other measured half, mitsuba
anisotropic specimens): ``bench/calibrate_log_rmse.py``, table in ``docs/science.md`` 7.1. The
witnesses were chosen by a leave-one-material-out cross-validation within the calibration set,
among error witnesses that enter with the sign of their mechanism; no witness of the arc (the
distinct azimuths per pair, the arc itself) lowered it by more than its noise, nor did one
after 24 fresh synthetic materials (18 anisotropic) joined the calibration set, whose refit
of this form the CV did not prefer beyond its noise (better on synthetic materials, worse on
the measured ones), so the coefficients were kept. The caps are the
largest witnesses of the scans it was fitted on: a power law fitted up to there says nothing beyond
(one measured material's leave-one-pair-out error reaches 66.5 with a condition-number design,
nearly four times the calibration's largest, 17.9). Within x2 of the truth on 76 % of the 440
validation scans and on 76 % of the 121 with the default half-turn design (a constant guess:
59 % and 68 %); it under-estimates measured materials read with the presets (x0.37-0.39 typically)
and over-estimates the anisotropic specimens read over half a turn (x1.43 typically with the
default design).
"""

from __future__ import annotations

import numpy as np

#: Features of :data:`LOG_RMSE_MODEL`, in the order :func:`predict_log_rmse` takes them.
LOG_RMSE_FEATURES: tuple[str, ...] = ("expected", "mahalanobis", "cv_sample_error")
#: ``(a, b, c, d)`` of ``predicted^2 = exp(a) expected^2 + exp(b) mahalanobis^c cv^d``.
LOG_RMSE_MODEL: tuple[float, float, float, float] = (0.873, -0.299, 0.653, 1.007)
#: ``(M, V)``: ``mahalanobis`` and ``cv_sample_error`` are capped here before the formula (the
#: largest values of the calibration scans; the model is not extrapolated beyond them).
LOG_RMSE_CAPS: tuple[float, float] = (2.428e-3, 17.88)

_FLOOR = 1e-12  # keeps the logarithms finite for exact (noise-free, in-span) data


def predict_log_rmse(expected: float, mahalanobis: float, cv_sample_error: float) -> float:
    """Calibrated estimate of the whole-table ``log_rmse`` of a joint reconstruction.

    Parameters
    ----------
    expected : float
        The posterior's expected ``log_rmse`` (dimensionless).
    mahalanobis : float
        Squared Mahalanobis norm of the fit per reading
        (:attr:`gonio.brdf.reconstruction.reconstruct.Reconstruction.mahalanobis`; remapped
        units squared).
    cv_sample_error : float
        Leave-one-pair-out relative error (:attr:`Reconstruction.cv_sample_error`, a fraction).

    Returns
    -------
    float
        The estimate (``log_rmse`` units); NaN when any input is NaN. ``mahalanobis`` and
        ``cv_sample_error`` above :data:`LOG_RMSE_CAPS` count as the cap.
    """
    x = (float(expected), float(mahalanobis), float(cv_sample_error))
    if not all(np.isfinite(v) for v in x):
        return float("nan")
    undetermined, outside = _log_terms(*x)
    # In logs, so tiny features do not underflow: ln(exp(a) e^2 + exp(b) m^c cv^d) / 2.
    return float(np.exp(0.5 * np.logaddexp(undetermined, outside)))


def _log_terms(expected: float, mahalanobis: float, cv_sample_error: float
               ) -> tuple[float, float]:
    """ln of the two variance terms of :data:`LOG_RMSE_MODEL` (finite inputs)."""
    e, m, cv = (max(v, _FLOOR) for v in (expected, mahalanobis, cv_sample_error))
    m, cv = min(m, LOG_RMSE_CAPS[0]), min(cv, LOG_RMSE_CAPS[1])
    a, b, c, d = LOG_RMSE_MODEL
    return a + 2.0 * np.log(e), b + c * np.log(m) + d * np.log(cv)


def estimate_parts(expected: float, mahalanobis: float,
                   cv_sample_error: float) -> tuple[float, float]:
    """The two parts of :func:`predict_log_rmse`, each in ``log_rmse`` units.

    ``(undetermined, outside)`` with ``undetermined^2 + outside^2 = predicted^2``: what the
    readings leave undetermined inside the basis (``sqrt(exp(a)) expected``) and what the
    basis cannot represent (``sqrt(exp(b) m^c cv^d)``). Which one dominates says why a scan's
    estimate is what it is (:mod:`gonio.designgap`).

    Returns
    -------
    (float, float)
        NaN, NaN when any input is NaN.
    """
    x = (float(expected), float(mahalanobis), float(cv_sample_error))
    if not all(np.isfinite(v) for v in x):
        return float("nan"), float("nan")
    undetermined, outside = _log_terms(*x)
    return float(np.exp(0.5 * undetermined)), float(np.exp(0.5 * outside))
