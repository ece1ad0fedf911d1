"""bench_selfestimate's in-plane candidate term (science.md 7.1.1): ``k s_in cv_log_error``."""

from __future__ import annotations

from types import ModuleType

import pytest

from tests.unit.bench_import import import_bench


@pytest.fixture(scope="module")
def bench() -> ModuleType:
    return import_bench("bench_selfestimate")


def test_the_term_is_the_share_times_the_leave_one_pair_out_error(bench: ModuleType) -> None:
    assert bench.in_plane_term(0.5, 0.4, 0.8) == pytest.approx(0.16)
    # The share is clipped to 0..1; a missing error or a zero coefficient adds nothing.
    assert bench.in_plane_term(1.7, 0.4, 0.8) == pytest.approx(0.32)
    assert bench.in_plane_term(-0.2, 0.4, 0.8) == 0.0
    assert bench.in_plane_term(1.0, float("nan"), 0.8) == 0.0
    assert bench.in_plane_term(1.0, 0.4, 0.0) == 0.0


def test_the_grid_and_the_fresh_set_are_as_written_down(bench: ModuleType) -> None:
    assert bench.IN_PLANE_GRID[0] == 0.0 and bench.IN_PLANE_GRID[-1] == pytest.approx(1.5)
    assert len(bench.FRESH_INPLANE) == 16
    assert not {n for n, *_ in bench.FRESH_INPLANE} & {n for n, *_ in bench.FRESH}


def _row(truth: float, shipped: float, plan: str = "MA98 r=8") -> dict[str, object]:
    """A fresh-confirm row whose shipped estimate is ``shipped``; an MA98-like layout (11 of
    19 pairs in the plane) with a large leave-one-pair-out error, unflagged."""
    return {"set": "fresh-confirm", "plan": plan, "truth": truth, "widened": shipped,
            "unwidened": shipped / 0.61, "uncovered": 0.0, "out_of_plane": 8 / 19,
            "cv_log_error": 0.5, "misfit_chi2": 0.5, "misfit_log": 0.0,
            "misfit_persistent_pairs": 0, "n": 19, "r": 8}


def test_the_confirmation_rule_adopts_only_fewer_low_scans_at_little_cost(
        bench: ModuleType, capsys: pytest.CaptureFixture[str]) -> None:
    assert bench.CONFIRM_K == 0.90 and len(bench.FRESH_CONFIRM) == 16
    older = {n for spec in (bench.FRESH, bench.FRESH_INPLANE) for n, *_ in spec}
    assert not {n for n, *_ in bench.FRESH_CONFIRM} & older
    # The term here: 0.9 * (11/19) * 0.5 = 0.26 added as a variance, so an estimate of 0.05
    # becomes sqrt(0.05^2 + 0.26^2) = 0.265.
    low = _row(truth=0.2, shipped=0.05)  # x0.25 shipped, x1.3 with the term
    assert bench.in_plane_candidate(low, bench.CONFIRM_K) == pytest.approx(
        (0.05 ** 2 + (0.9 * 11 / 19 * 0.5) ** 2) ** 0.5, rel=1e-6)
    fine = _row(truth=0.05, shipped=0.05)  # x1 shipped, x5.3 with the term
    assert bench.confirm_in_plane([low, fine]) is True  # one low saved, one within x2 lost
    assert bench.confirm_in_plane([fine]) is False  # nothing low to save
    # Six within x2 lost for one saved: a net loss of five, beyond the slack of four.
    assert bench.confirm_in_plane([low] + [fine] * 6) is False
    assert bench.confirm_in_plane([low] + [fine] * 5) is True
    assert bench.confirm_in_plane([{**low, "set": "fresh"}]) is None
    assert "confirmation rule" in capsys.readouterr().out


def test_the_highlight_candidates_and_the_blind_set_are_as_written_down(
        bench: ModuleType) -> None:
    """The highlight widening (science.md 7.1.1): at parameter 0 both forms are the mapping
    without the term; "variance" at the shipped scale is the shipped mapping; "widen" moves
    only scans above the warning's limit; the blind set is new."""
    import math

    from gonio.brdf.reconstruction.selfcheck import FINAL_HIGHLIGHT_SCALE, final_log_rmse

    row = {"unwidened": 0.05, "uncovered": 0.04, "peak_excess": 0.0, "misfit_chi2": 0.5,
           "misfit_log": 0.0, "misfit_persistent_pairs": 0, "n": 10, "r": 8,
           "highlight_excess": math.exp(3.0)}
    plain = math.hypot(0.61 * 0.05, 0.19 * 0.2)
    assert bench.highlight_candidate(row, "widen", 0.0) == pytest.approx(plain)
    assert bench.before_highlight(row) == pytest.approx(plain)
    assert bench.highlight_candidate(row, "variance", FINAL_HIGHLIGHT_SCALE) == pytest.approx(
        final_log_rmse(0.05, 0.04, bench.row_misfit(row), highlight_excess=math.exp(3.0)))
    assert bench.highlight_candidate(row, "widen", 1.0) == pytest.approx(
        plain * math.exp(3.0) / 3.4)
    below = {**row, "highlight_excess": 3.0}
    assert bench.highlight_candidate(below, "widen", 1.0) == pytest.approx(plain)
    assert bench.excess_of({**row, "highlight_excess": float("nan")}) == 1.0
    assert len(bench.FRESH_WIDE) == 12
    older = {n for s in (bench.FRESH, bench.FRESH_INPLANE, bench.FRESH_CONFIRM) for n, *_ in s}
    assert not {n for n, *_ in bench.FRESH_WIDE} & older


def test_the_under_prediction_candidate_and_its_blind_set_are_as_written_down(
        bench: ModuleType) -> None:
    """The leave-one-pair-out under-prediction term (science.md 7.1.1): ``v u`` added as a
    variance beside the coverage and highlight terms; at ``v`` = 0 the shipped estimate; the
    grid 0-0.10; the blind set is new."""
    import math

    row = {"unwidened": 0.05, "uncovered": 0.04, "peak_excess": 0.0, "misfit_chi2": 0.5,
           "misfit_log": 0.0, "misfit_persistent_pairs": 0, "n": 10, "r": 8,
           "highlight_excess": 1.0, "cv_log_under": 1.5, "cv_log_error": 2.0}
    plain = math.hypot(0.61 * 0.05, 0.19 * 0.2)
    assert bench.under_candidate(row, 0.0) == pytest.approx(plain)
    assert bench.under_candidate(row, 0.02) == pytest.approx(
        math.sqrt((0.61 * 0.05) ** 2 + 0.19**2 * 0.04 + (0.02 * 1.5) ** 2))
    assert bench.under_candidate(row, 0.02, "cv_log_error") == pytest.approx(
        math.sqrt((0.61 * 0.05) ** 2 + 0.19**2 * 0.04 + (0.02 * 2.0) ** 2))
    assert bench.under_candidate({**row, "cv_log_under": float("nan")}, 0.02) == pytest.approx(
        plain)
    assert bench.UNDER_GRID[0] == 0.0 and bench.UNDER_GRID[-1] == pytest.approx(0.10)
    assert len(bench.FRESH_COAT) == 12
    older = {n for s in (bench.FRESH, bench.FRESH_INPLANE, bench.FRESH_CONFIRM,
                         bench.FRESH_WIDE) for n, *_ in s}
    assert not {n for n, *_ in bench.FRESH_COAT} & older


def test_the_coverage_shrink_candidate_is_as_written_down(bench: ModuleType) -> None:
    """The coverage shrink (science.md 7.1.1.1): for a designed layout the coverage term
    ``0.19 sqrt(uncovered)`` times ``min(1, cv/c)`` or ``min(1, sqrt(cv/c))``; a preset's and a
    scan with ``cv >= c`` keep the shipped estimate ``sqrt((0.61 p)^2 + 0.19^2 u)``."""
    import math

    designed = sorted(bench.DESIGNED_PLANS)[0]
    assert "MA98 r=8" not in bench.DESIGNED_PLANS
    row = {"unwidened": 0.05, "uncovered": 0.04, "peak_excess": 0.0, "misfit_chi2": 0.5,
           "misfit_log": 0.0, "misfit_persistent_pairs": 0, "n": 10, "r": 8,
           "highlight_excess": 1.0, "cv_log_under": 0.0, "cv_log_error": 0.0525,
           "plan": designed}
    model = 0.61 * 0.05
    plain = math.hypot(model, 0.19 * 0.2)
    # cv / c = 1/4: the term halves (square root) or falls to a quarter (linear).
    assert bench.cov_candidate(row, "cov-sqrt", 0.21) == pytest.approx(
        math.hypot(model, 0.19 * 0.2 * 0.5))
    assert bench.cov_candidate(row, "cov-linear", 0.21) == pytest.approx(
        math.hypot(model, 0.19 * 0.2 * 0.25))
    assert bench.cov_candidate({**row, "cv_log_error": 0.3}, "cov-sqrt", 0.21) == (
        pytest.approx(plain))
    assert bench.cov_candidate({**row, "plan": "MA98 r=8"}, "cov-sqrt", 0.21) == (
        pytest.approx(plain))
    with pytest.raises(ValueError, match="unknown form"):
        bench.cov_candidate(row, "cov-cube", 0.21)
