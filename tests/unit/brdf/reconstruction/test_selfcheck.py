"""Tests of the self-estimate ``predicted_log_rmse`` and its witnesses (issue 9 item 5)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from gonio.brdf.highlightread import highlight_read
from gonio.brdf.reconstruction.basis import inverse_remap
from gonio.brdf.reconstruction.posterior import ScanPosterior
from gonio.brdf.reconstruction.reconstruct import reconstruct
from gonio.brdf.reconstruction.selfcheck import (
    LOG_RMSE_CAPS,
    LOG_RMSE_MODEL,
    VF_LOG_RMSE_MODEL,
    final_log_rmse,
    predict_joint_log_rmse,
    predict_vf_log_rmse,
)
from gonio.brdf.tables import geometry as geo
from tests.unit.brdf.reconstruction.test_posterior import _scan


def _dense_mahalanobis(post: ScanPosterior, alpha: np.ndarray) -> float:
    """``f^T K^-1 f / (n C)`` with the readings' prior covariance ``K`` written out element by
    element and the fit ``f = K (K + eta I)^-1 y`` (no harmonic or Cholesky shortcuts)."""
    P = np.asarray(post.P)
    rho_m = np.where(np.arange(P.shape[0]) > 0, post.rho, 1.0)
    Qt = post.Qt
    ph_read = (post.ph_lab[:, None] - alpha[None, :]).ravel()
    q = np.repeat(np.arange(Qt.shape[0]), alpha.size)
    N = ph_read.size
    K = np.empty((N, N))
    for a in range(N):
        for b in range(N):
            d = ph_read[a] - ph_read[b]
            prior = sum(rho_m[m] * P[m] * np.cos(m * d) for m in range(P.shape[0]))
            K[a, b] = Qt[q[a]] @ prior @ Qt[q[b]]
    total = 0.0
    for c in range(post.y.shape[1]):
        f = K @ np.linalg.solve(K + post.eta * np.eye(N), post.y[:, c])
        total += float(f @ np.linalg.solve(K, f))
    return total / (Qt.shape[0] * post.y.shape[1])


def test_mahalanobis_equals_the_explicit_norm_of_the_fit() -> None:
    b, cells, ph, alpha, vals = _scan()
    post = ScanPosterior(b, cells, ph, alpha, vals, lam=0.0, rho=2.0)
    assert post.mahalanobis > 0
    assert post.mahalanobis == pytest.approx(_dense_mahalanobis(post, alpha), rel=1e-6)


def test_mahalanobis_grows_with_the_distance_from_the_library_mean() -> None:
    """Readings at the library's mean need no departure from the prior (norm 0); readings
    t times as far from the mean (in remapped units) need t^2 times the norm."""
    b, cells, ph, alpha, vals = _scan()
    post = ScanPosterior(b, cells, ph, alpha, vals, lam=0.0, rho=2.0)
    th, td, pd = np.asarray(cells).T
    rows, weights = b.neighbours(th, td, pd)
    fmed = (weights * b.f_med[rows]).sum(axis=1)[:, None, None]
    mu = (weights * b.mu[rows]).sum(axis=1)[:, None, None]
    ci, co = geo.cell_cosines(th, td, pd)
    w = np.maximum(ci * co, b.eps)[:, None, None]
    y0 = post.y.reshape(vals.shape)

    def norm(t: float) -> float:
        v = np.maximum(inverse_remap(mu + t * y0, fmed, w, b.eps), 0.0)
        return ScanPosterior(b, cells, ph, alpha, v, lam=0.0, rho=2.0).mahalanobis

    assert abs(norm(0.0)) < 1e-9 * post.mahalanobis
    assert norm(0.5) == pytest.approx(0.25 * post.mahalanobis, rel=1e-6)
    assert norm(1.0) == pytest.approx(post.mahalanobis, rel=1e-6)


def test_prediction_is_the_two_term_formula() -> None:
    """Evaluated by hand: predicted^2 = e^a expected^2 + e^b mahalanobis^c cv^d."""
    a, b, c, d = LOG_RMSE_MODEL
    for e, m, cv in ((0.02, 3e-5, 0.4), (0.005, 1e-6, 2.0), (0.1, 1e-3, 0.05)):
        want = math.sqrt(math.exp(a) * e * e + math.exp(b) * m**c * cv**d)
        assert predict_joint_log_rmse(e, m, cv) == pytest.approx(want, rel=1e-12)


def test_witnesses_beyond_the_calibration_count_as_the_cap() -> None:
    """Above LOG_RMSE_CAPS the discrepancy term stops growing: by hand, at the caps."""
    a, b, c, d = LOG_RMSE_MODEL
    m_cap, cv_cap = LOG_RMSE_CAPS
    e = 0.02
    at_caps = math.sqrt(math.exp(a) * e * e + math.exp(b) * m_cap**c * cv_cap**d)
    for m, cv in ((10 * m_cap, 5 * cv_cap), (m_cap, 100 * cv_cap), (1e3 * m_cap, cv_cap)):
        assert predict_joint_log_rmse(e, m, cv) == pytest.approx(at_caps, rel=1e-12)
    # Below the caps both witnesses still count in full.
    half = math.sqrt(math.exp(a) * e * e + math.exp(b) * (m_cap / 2) ** c * cv_cap**d)
    assert predict_joint_log_rmse(e, m_cap / 2, 10 * cv_cap) == pytest.approx(half, rel=1e-12)
    assert half < at_caps


def test_prediction_limits() -> None:
    a = LOG_RMSE_MODEL[0]
    # A fit at the library's mean (no discrepancy): the posterior term alone. The witness is
    # floored at 1e-12 to keep the logarithm finite, which leaves a discrepancy term of order
    # 1e-12^c (c below 1: about 1e-6 of the total here), hence the tolerance.
    assert predict_joint_log_rmse(0.03, 1e-300, 0.5) == pytest.approx(math.exp(a / 2) * 0.03,
                                                                     rel=1e-5)
    # It never falls below the posterior term, and grows with either witness.
    p0 = predict_joint_log_rmse(0.03, 3e-5, 0.5)
    assert p0 > math.exp(a / 2) * 0.03
    assert predict_joint_log_rmse(0.03, 3e-4, 0.5) > p0
    assert predict_joint_log_rmse(0.03, 3e-5, 2.0) > p0
    for bad in ((float("nan"), 1e-5, 0.1), (0.01, float("nan"), 0.1), (0.01, 1e-5, float("nan"))):
        assert math.isnan(predict_joint_log_rmse(*bad))


def test_vf_prediction_is_the_power_law_of_cv_and_scan_size() -> None:
    """Evaluated by hand: predicted = e^a cv^b (n r)^c, from the cross-validation error and
    the number of readings alone; undefined without a cross-validation error."""
    a, b, c = VF_LOG_RMSE_MODEL
    for cv, n, r in ((0.2, 10, 8), (1.0, 1, 1), (3.5, 6, 16)):
        want = math.exp(a) * cv**b * (n * r) ** c
        assert predict_vf_log_rmse(cv, n, r) == pytest.approx(want, rel=1e-12)
    assert predict_vf_log_rmse(1.0, 1, 1) == pytest.approx(math.exp(a), rel=1e-12)
    assert math.isnan(predict_vf_log_rmse(float("nan"), 10, 8))


def test_reconstruction_reports_the_witnesses_it_predicts_from() -> None:
    b, cells, ph, alpha, vals = _scan()
    rec = reconstruct(b, cells, ph, alpha, vals, channels=["Y"])
    # The posterior's log_rmse weights come from the fit under the learnt prior, before the
    # fit adopts the scan's own rho (reconstruct's notes: one posterior per call).
    plain = reconstruct(b, cells, ph, alpha, vals, channels=["Y"], rho=None)
    post = ScanPosterior(b, cells, ph, alpha, vals, table=plain.table.values)
    assert rec.mahalanobis == pytest.approx(post.mahalanobis, rel=1e-9)
    assert rec.expected_log_rmse == pytest.approx(post.expected_log_rmse, rel=1e-9)
    assert rec.predicted_log_rmse_unwidened == pytest.approx(
        predict_joint_log_rmse(rec.expected_log_rmse, rec.mahalanobis, rec.cv_sample_error),
        rel=1e-9)
    # The coverage witness of the final mapping is the same posterior's.
    assert rec.uncovered_share == pytest.approx(post.uncovered_share(), rel=1e-9)
    # With the highlight term of the table's own highlight_excess and the under-prediction
    # term of its own cv_log_under (docs/science.md 7.1.1).
    read = highlight_read(rec.table, cells, ph, alpha, np.maximum(vals, 0.0))
    assert rec.highlight_excess == pytest.approx(read.excess, rel=1e-12)
    # The whole read travels with the result (finishing reports it rather than reading again).
    assert rec.highlight is not None
    assert rec.highlight.as_metrics() == pytest.approx(read.as_metrics(), rel=1e-12,
                                                       nan_ok=True)
    assert rec.predicted_log_rmse == pytest.approx(final_log_rmse(
        rec.predicted_log_rmse_unwidened, rec.uncovered_share, rec.misfit,
        highlight_excess=rec.highlight_excess, cv_log_under=rec.cv_log_under), rel=1e-9)
    vf = reconstruct(b, cells, ph, alpha, vals, channels=["Y"], method="vf")
    assert math.isnan(vf.mahalanobis) and math.isnan(vf.expected_log_rmse)
    assert math.isnan(vf.uncovered_share)
