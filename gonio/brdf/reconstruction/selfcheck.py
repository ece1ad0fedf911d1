"""``predicted_log_rmse``: the self-estimated error of a joint reconstruction (issue 9 item 5).

Two things make a reconstruction's ``log_rmse`` against the true BRDF large, and each has its
own witness in the scan:

* **what the readings leave undetermined** inside the basis: the joint fit's posterior
  variance, weighted as ``log_rmse`` weighs errors and scaled to the material by empirical
  Bayes (:attr:`gonio.brdf.reconstruction.posterior.ScanPosterior.expected_log_rmse`, ``expected``);
* **what the basis cannot represent**: invisible to the posterior, but it shows as
  readings the fit to the *other* pairs mispredicts (``cv_sample_error``, the
  leave-one-pair-out relative error; its log-unit twin ``cv_log_error`` predicted less well).

The estimate is ``exp(a) expected^b cv_sample_error^c`` (:data:`LOG_RMSE_MODEL`), fitted in
logs on held-out training materials (the synthetic panel of
:mod:`gonio.brdf.design.heldout` and half of the measured materials) and checked on
materials never calibrated on (the other measured half, mitsuba anisotropic specimens):
``bench/calibrate_log_rmse.py``, table in
``docs/science.md`` 7.1. The posterior term carries most of the information (exponent 0.74);
the remaining spread is the unrepresentable part, which no sample-based witness measured
well.
"""

from __future__ import annotations

import numpy as np

#: Features of :data:`LOG_RMSE_MODEL`, in order after the intercept.
LOG_RMSE_FEATURES: tuple[str, ...] = ("expected", "cv_sample_error")
#: ``ln(predicted_log_rmse) = a + b ln(expected) + c ln(cv_sample_error)``.
LOG_RMSE_MODEL: tuple[float, float, float] = (0.109, 0.741, 0.176)


def predict_log_rmse(expected: float, cv_sample_error: float) -> float:
    """Calibrated estimate of the whole-table ``log_rmse`` of a joint reconstruction.

    Parameters
    ----------
    expected : float
        The posterior's expected ``log_rmse`` (dimensionless).
    cv_sample_error : float
        Leave-one-pair-out relative error (:attr:`Reconstruction.cv_sample_error`).

    Returns
    -------
    float
        NaN when either input is NaN.
    """
    if not (np.isfinite(expected) and np.isfinite(cv_sample_error)):
        return float("nan")
    a, b, c = LOG_RMSE_MODEL
    return float(np.exp(a) * max(float(expected), 1e-6) ** b
                 * max(float(cv_sample_error), 1e-6) ** c)
