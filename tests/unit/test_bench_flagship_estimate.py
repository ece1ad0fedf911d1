"""bench/bench_flagship_estimate.py's bisections against the closed form of the final mapping
for an unflagged scan with no highlight or under-prediction term:
``estimate^2 = (0.61 unwidened)^2 + coverage^2`` (docs/science.md 7.1.1)."""

from __future__ import annotations

import math
from types import ModuleType
from typing import Any

import pytest

from tests.unit.bench_import import import_bench


@pytest.fixture(scope="module")
def fe() -> ModuleType:
    return import_bench("bench_flagship_estimate")


def _row(truth: float, unwidened: float, uncovered: float) -> dict[str, Any]:
    return {"truth": truth, "unwidened": unwidened, "uncovered": uncovered,
            "highlight_excess": 1.0, "cv_log_under": 0.0, "peak_excess": 0.0,
            "misfit_chi2": 0.5, "misfit_log": 0.0, "misfit_persistent_pairs": 0,
            "n": 12, "r": 8, "mahalanobis": 1e-4}


def test_needed_coverage_is_the_closed_form(fe: ModuleType) -> None:
    # Half the truth is 0.05; the model's part 0.61 * 0.04 = 0.0244; the coverage term that
    # brings the estimate to 0.05 is sqrt(0.05^2 - 0.0244^2) = 0.04364.
    row = _row(truth=0.1, unwidened=0.04, uncovered=0.2)
    assert fe.needed_coverage(row) == pytest.approx(math.sqrt(0.05**2 - 0.0244**2), rel=1e-6)


def test_needed_coverage_none_when_low_already_and_zero_when_never_low(fe: ModuleType) -> None:
    # Shipped: sqrt(0.0244^2 + 0.19^2 * 0.01) = 0.0310 < half of 0.1: low already.
    assert fe.needed_coverage(_row(truth=0.1, unwidened=0.04, uncovered=0.01)) is None
    # The model's part alone, 0.0244, is above half of 0.04.
    assert fe.needed_coverage(_row(truth=0.04, unwidened=0.04, uncovered=0.05)) == 0.0


def test_largest_coverage_within_x2_is_the_closed_form(fe: ModuleType) -> None:
    # Twice the truth 0.032, model part 0.61 * 0.013 = 0.00793: sqrt(0.032^2 - 0.00793^2).
    row = _row(truth=0.016, unwidened=0.013, uncovered=0.07)
    assert fe.largest_coverage_within_x2(row) == pytest.approx(
        math.sqrt(0.032**2 - 0.00793**2), rel=1e-6)


def test_cap_lowers_only_above_k_sqrt_mahalanobis(fe: ModuleType) -> None:
    row = _row(truth=0.016, unwidened=0.013, uncovered=0.07)  # shipped coverage 0.0503
    assert fe.cap_estimate(row, 1e3) == pytest.approx(fe.estimate(row))
    # k sqrt(1e-4) = 0.02 at k = 2: the estimate is sqrt(0.00793^2 + 0.02^2).
    assert fe.cap_estimate(row, 2.0) == pytest.approx(math.hypot(0.00793, 0.02), rel=1e-6)
