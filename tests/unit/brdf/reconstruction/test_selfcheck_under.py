"""The leave-one-pair-out under-prediction term of the self-estimate (``selfcheck.under_term``;
docs/science.md 7.1.1).

Cases known by construction: the term is ``FINAL_UNDER_SCALE cv_log_under`` and adds as a
variance beside the coverage and highlight terms; a scan one of whose pairs reads a peak the
others do not predict (its readings multiplied by 50) has a larger ``cv_log_under``, and the
reported estimate is the mapping with exactly the term of the reconstruction's own value."""

from __future__ import annotations

import math

import pytest

from gonio.brdf.reconstruction.reconstruct import reconstruct
from gonio.brdf.reconstruction.selfcheck import (
    FINAL_COVERAGE_SCALE,
    FINAL_FLAGGED_FACTOR,
    FINAL_PREDICTED_FACTOR,
    FINAL_UNDER_SCALE,
    BasisMisfit,
    final_log_rmse,
    final_parts,
    predict_joint_log_rmse,
    under_term,
)
from tests.unit.brdf.reconstruction.test_posterior import _scan

QUIET = BasisMisfit(chi2=0.5, log_misfit=0.0, persistent_pairs=0, n_pairs=10, n_angles=8)
FLAGGED = BasisMisfit(chi2=900.0, log_misfit=0.5, persistent_pairs=6, n_pairs=10, n_angles=8)


def test_the_term_is_the_scale_times_the_under_prediction() -> None:
    assert FINAL_UNDER_SCALE == 0.0425
    assert under_term(1.5) == pytest.approx(1.5 * 0.0425)
    # Nothing to add without a leave-one-pair-out error, or with none above its prediction.
    assert under_term(0.0) == 0.0
    assert under_term(float("nan")) == 0.0
    assert under_term(-1.0) == 0.0


def test_it_adds_as_a_variance_beside_the_coverage_and_highlight_terms() -> None:
    p, u, w = 0.04, 0.09, 2.0
    cov = FINAL_COVERAGE_SCALE * math.sqrt(u)
    assert final_log_rmse(p, u, QUIET, cv_log_under=w) == pytest.approx(
        math.sqrt((FINAL_PREDICTED_FACTOR * p) ** 2 + cov**2 + (0.0425 * w) ** 2))
    hl = 0.025 * math.log(math.exp(3.0))
    assert final_log_rmse(p, u, QUIET, cv_log_under=w, highlight_excess=math.exp(3.0)) == (
        pytest.approx(math.sqrt((FINAL_PREDICTED_FACTOR * p) ** 2 + cov**2 + hl**2
                                + (0.0425 * w) ** 2)))
    # Flagged: the same under the flagged factor, and still never below the misfit.
    assert final_log_rmse(p, u, FLAGGED, cv_log_under=w) == pytest.approx(
        max(math.sqrt((FINAL_FLAGGED_FACTOR * p) ** 2 + cov**2 + (0.0425 * w) ** 2), 0.5))
    assert final_log_rmse(p, u, QUIET) == final_log_rmse(p, u, QUIET, cv_log_under=0.0)


def test_the_parts_still_add_up_to_the_estimate() -> None:
    e, m, cv, u, w = 0.03, 1e-3, 0.4, 0.2, 1.2
    parts = final_parts(e, m, cv, u, QUIET, cv_log_under=w)
    assert parts[2] == pytest.approx(math.hypot(FINAL_COVERAGE_SCALE * math.sqrt(u),
                                                FINAL_UNDER_SCALE * w))
    assert math.hypot(*parts) == pytest.approx(
        final_log_rmse(predict_joint_log_rmse(e, m, cv), u, QUIET, cv_log_under=w))


def test_a_pair_reading_a_peak_the_others_do_not_predict_widens_the_estimate() -> None:
    """The same scan twice, once with one pair's readings multiplied by 50: the other pairs
    predict that pair far too low, so ``cv_log_under`` grows, and in both the reported estimate
    is the mapping with exactly the terms of the reconstruction's own witnesses."""
    b, cells, ph, alpha, vals = _scan()
    spiked = vals.copy()
    spiked[2] *= 50.0
    under = []
    for v in (vals, spiked):
        rec = reconstruct(b, cells, ph, alpha, v, channels=["Y"])
        assert rec.misfit is not None
        assert 0.0 <= rec.cv_log_under <= rec.cv_log_error + 1e-12
        want = final_log_rmse(rec.predicted_log_rmse_unwidened, rec.uncovered_share,
                              rec.misfit, highlight_excess=rec.highlight_excess,
                              cv_log_under=rec.cv_log_under)
        assert rec.predicted_log_rmse == pytest.approx(
            max(want, rec.peak_excess_log_rmse), rel=1e-9)
        under.append(rec.cv_log_under)
    assert under[1] > 3.0 * under[0] and under[1] > 0.5
