"""Tests of the whole-job time estimate (gonio.timeleft): finishing from the last scans."""

from __future__ import annotations

from typing import Any

import pytest

from gonio.jobstates import JobState
from gonio.store import JobRow
from gonio.timeleft import FINISHING_FALLBACK_S, finishing_estimate, time_left


def _row(job_id: int, kind: str = "uniform", summary: dict[str, Any] | None = None) -> JobRow:
    return JobRow(id=job_id, state=JobState.COMPLETED, kind=kind, specimen="s", priority=0,
                  position=0.0, created=0.0, started=0.0, finished=1.0, plan={}, rig={},
                  reason=None, result_path=None, summary=summary, done_angles=4,
                  total_angles=4)


def test_no_finished_scan_gives_the_measured_default_and_says_so() -> None:
    est = finishing_estimate([_row(1, "calibration", {"seconds": 0.4}), _row(2, summary=None)])
    assert est.seconds == FINISHING_FALLBACK_S
    assert "no scan has finished" in est.source


def test_one_scan_gives_its_own_finishing() -> None:
    est = finishing_estimate([_row(3, summary={"seconds": 7.5})])
    assert est.seconds == 7.5 and "job 3" in est.source


def test_the_median_of_the_newest_three_scans_calibrations_left_out() -> None:
    rows = [_row(1, summary={"seconds": 130.0}),  # the first scan, which built the basis
            _row(2, summary={"seconds": 4.0}), _row(5, "calibration", {"seconds": 0.1}),
            _row(4, summary={"seconds": 6.0}), _row(3, summary={"seconds": 5.0}),
            _row(6, summary={"seconds": "n/a"})]
    est = finishing_estimate(rows)
    # Jobs 2, 3, 4 are the newest three scans with a measured time: median of 4, 5, 6 s.
    assert est.seconds == 5.0
    assert "2, 3, 4" in est.source and "median" in est.source


@pytest.mark.parametrize(("eta", "build", "finishing", "elapsed", "expected"), [
    (30.0, None, 5.0, None, 35.0),      # measuring: 30 s, then 5 s finishing
    (30.0, 120.0, 5.0, None, 155.0),    # a basis build between them
    (None, None, 5.0, None, None),      # no measuring estimate yet: no total either
    (None, None, 5.0, 2.0, 3.0),        # reconstructing for 2 s of 5
    (12.0, None, 5.0, 9.0, None),       # over its estimate: unknown, not 0 s left
    (None, None, 5.0, 5.0, None),       # at its estimate and not done: unknown
    (None, 120.0, 5.0, 20.0, 105.0),    # building the basis for 20 s of 120, then 5 s
])
def test_time_left_adds_what_follows_measuring(eta: float | None, build: float | None,
                                              finishing: float, elapsed: float | None,
                                              expected: float | None) -> None:
    assert time_left(eta, build, finishing, elapsed) == expected
