"""The highlight term of the self-estimate (``selfcheck.highlight_term``; docs/science.md 7.1.1).

Cases known by construction: the term is ``FINAL_HIGHLIGHT_SCALE ln(excess)`` and adds as a
variance beside the coverage term; a reconstruction whose highlight no reading comes near
(a narrow lobe read only far from its peak) is widened by exactly that term."""

from __future__ import annotations

import math

import numpy as np
import pytest

from gonio.brdf.highlightread import highlight_read
from gonio.brdf.reconstruction.reconstruct import reconstruct
from gonio.brdf.reconstruction.selfcheck import (
    FINAL_COVERAGE_SCALE,
    FINAL_FLAGGED_FACTOR,
    FINAL_HIGHLIGHT_SCALE,
    FINAL_PREDICTED_FACTOR,
    BasisMisfit,
    final_log_rmse,
    final_parts,
    highlight_term,
    predict_joint_log_rmse,
)
from tests.unit.brdf.reconstruction.test_posterior import _scan

QUIET = BasisMisfit(chi2=0.5, log_misfit=0.0, persistent_pairs=0, n_pairs=10, n_angles=8)
FLAGGED = BasisMisfit(chi2=900.0, log_misfit=0.5, persistent_pairs=6, n_pairs=10, n_angles=8)


def test_the_term_is_the_scale_times_the_log_of_the_excess() -> None:
    # A table peaking e^4 times above its brightest reading: 4 natural-log units unread.
    assert highlight_term(math.exp(4.0)) == pytest.approx(4.0 * FINAL_HIGHLIGHT_SCALE)
    assert highlight_term(math.exp(2.0), scale=0.1) == pytest.approx(0.2)
    # Read (the table no brighter than the brightest reading) or unknown: nothing added.
    for excess in (1.0, 0.3, 0.0, -2.0, float("nan"), float("inf") * 0):
        assert highlight_term(excess) == 0.0


def test_it_adds_as_a_variance_beside_the_coverage_term() -> None:
    p, u, e = 0.04, 0.02, math.exp(3.0)
    cov = FINAL_COVERAGE_SCALE * math.sqrt(u)
    term = 3.0 * FINAL_HIGHLIGHT_SCALE
    assert final_log_rmse(p, u, QUIET, highlight_excess=e) == pytest.approx(
        math.sqrt((FINAL_PREDICTED_FACTOR * p) ** 2 + cov**2 + term**2))
    # The default excess of 1 is the mapping without the term.
    assert final_log_rmse(p, u, QUIET) == pytest.approx(
        math.hypot(FINAL_PREDICTED_FACTOR * p, cov))
    # A flagged scan: its own factor, the term, and still never below the misfit.
    assert final_log_rmse(p, u, FLAGGED, highlight_excess=e) == pytest.approx(max(
        math.sqrt((FINAL_FLAGGED_FACTOR * p) ** 2 + cov**2 + term**2), 0.5))
    big = math.exp(40.0)  # term 1.0, above the misfit 0.5
    assert final_log_rmse(p, u, FLAGGED, highlight_excess=big) == pytest.approx(
        math.sqrt((FINAL_FLAGGED_FACTOR * p) ** 2 + cov**2 + (40 * FINAL_HIGHLIGHT_SCALE) ** 2))


def test_the_parts_still_add_up_to_the_estimate() -> None:
    e, m, cv, u, x = 0.03, 1e-3, 0.4, 0.2, 50.0
    parts = final_parts(e, m, cv, u, QUIET, highlight_excess=x)
    assert parts[2] == pytest.approx(math.hypot(FINAL_COVERAGE_SCALE * math.sqrt(u),
                                                FINAL_HIGHLIGHT_SCALE * math.log(x)))
    assert math.hypot(*parts) == pytest.approx(
        final_log_rmse(predict_joint_log_rmse(e, m, cv), u, QUIET, highlight_excess=x))


def test_a_scan_whose_brightest_readings_are_dimmed_is_widened_by_the_term() -> None:
    """The same scan twice, once with every reading brighter than the median divided by 40:
    the table's peak then stands further above every reading (its highlight is not read), and
    in both the reported estimate is the mapping with exactly the term of the
    reconstruction's own ``highlight_excess``, above the mapping without it."""
    b, cells, ph, alpha, vals = _scan()
    dim = np.where(vals > np.median(vals), vals / 40.0, vals)
    excess = []
    for v in (vals, dim):
        rec = reconstruct(b, cells, ph, alpha, v, channels=["Y"])
        want = highlight_read(rec.table, cells, ph, alpha, np.maximum(v, 0.0)).excess
        assert rec.highlight_excess == pytest.approx(want, rel=1e-12)
        assert rec.highlight_excess > 1.0
        assert rec.misfit is not None
        before = final_log_rmse(rec.predicted_log_rmse_unwidened, rec.uncovered_share,
                                rec.misfit)
        with_term = final_log_rmse(rec.predicted_log_rmse_unwidened, rec.uncovered_share,
                                   rec.misfit, highlight_excess=rec.highlight_excess)
        assert with_term > before
        # Since 2026-11-28 the estimate also carries the under-prediction term of the scan's
        # own cv_log_under (test_selfcheck_under.py).
        reported = final_log_rmse(rec.predicted_log_rmse_unwidened, rec.uncovered_share,
                                  rec.misfit, highlight_excess=rec.highlight_excess,
                                  cv_log_under=rec.cv_log_under)
        assert rec.predicted_log_rmse == pytest.approx(
            max(reported, rec.peak_excess_log_rmse), rel=1e-9)
        excess.append(rec.highlight_excess)
    assert excess[1] > 3.0 * excess[0]
