"""Tests of the whole-job time estimate (gonio.timeleft): finishing from the last scans."""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import pytest

from gonio.jobstates import JobState
from gonio.store import JobRow
from gonio.timeleft import (
    FINISHING_FALLBACK_S,
    QueuedRun,
    finishing_estimate,
    most_channels,
    start_estimates,
    time_left,
)


def _row(job_id: int, kind: str = "uniform", summary: dict[str, Any] | None = None) -> JobRow:
    return JobRow(id=job_id, state=JobState.COMPLETED, kind=kind, specimen="s", priority=0,
                  position=0.0, created=0.0, started=0.0, finished=1.0, plan={}, rig={},
                  reason=None, result_path=None, summary=summary, done_angles=4,
                  total_angles=4)


def test_no_finished_scan_gives_the_measured_default_and_says_so() -> None:
    est = finishing_estimate([_row(1, "calibration", {"seconds": 0.4}), _row(2, summary=None)])
    assert est.seconds == FINISHING_FALLBACK_S
    assert "no scan has finished" in est.source


def test_before_any_scan_a_spectral_rig_expects_a_longer_finishing() -> None:
    """31 bands finished in 9.5-9.9 s where the RGB rig's scan took 6.2-7.1 s (measured,
    timeleft.FALLBACK_S_PER_CHANNEL): 7.5 s + 28 x 0.1 s = 10.3 s, and the source says so;
    three channels or fewer keep the measured default."""
    est = finishing_estimate([], channels=31)
    assert est.seconds == pytest.approx(10.3)
    assert est.source == ("no scan has finished on this job store yet: 10.3 s, the default "
                          "scan's measured finishing and 0.1 s for each of 28 channels beyond "
                          "three")
    assert finishing_estimate([], channels=1).seconds == FINISHING_FALLBACK_S



def test_only_scans_read_with_as_many_channels_count() -> None:
    """One store can hold RGB and 31-band scans (a lab swaps sensors; `gonio scan --sim` and
    `--material metallic-blue-paint` share a data directory): each rig's estimate takes the
    scans with its own channel count, and says the others were left out."""
    def scan(job_id: int, seconds: float, channels: int) -> JobRow:
        return replace(_row(job_id, summary={"seconds": seconds}),
                       rig={"sensors": [{"channels": [f"c{i}" for i in range(channels)]}]})
    rows = [scan(1, 10.0, 31), scan(2, 6.0, 3), scan(3, 9.0, 31), scan(4, 7.0, 3)]
    spectral = finishing_estimate(rows, channels=31)
    assert spectral.seconds == pytest.approx(9.5)  # jobs 1 and 3: (10 + 9) / 2
    assert spectral.source == ("the median of jobs 1, 3 on this job store; scans read with "
                               "other than 31 channels are not counted")
    assert finishing_estimate(rows, channels=3).seconds == pytest.approx(6.5)  # jobs 2, 4
    # None with the rig's channels: the fallback, which does not claim no scan finished.
    none = finishing_estimate(rows[1:2], channels=31)
    assert none.seconds == pytest.approx(10.3)
    assert none.source.startswith("no scan with 31 channels has finished on this job store")


def test_most_channels_reads_the_widest_sensor() -> None:
    from types import SimpleNamespace

    rig = SimpleNamespace(sensors=[SimpleNamespace(channels=("R", "G", "B")),
                                   SimpleNamespace(channels=tuple(f"b{i}" for i in range(31)))])
    assert most_channels(rig) == 31
    assert most_channels(SimpleNamespace(sensors=[])) == 3
    # A job's stored rig (JSON); one older code stored in another shape counts as none.
    assert most_channels({"sensors": [{"channels": ["R", "G", "B", "NIR"]}]}) == 4
    assert most_channels({}) == most_channels({"sensors": "x"}) == 3


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


def test_each_queued_job_starts_after_the_rig_is_free_and_the_jobs_ahead() -> None:
    runs = [QueuedRun(4, 30.0), QueuedRun(5, 45.0), QueuedRun(6, 10.0)]
    starts = start_estimates(100.0, False, "job 3's time left", runs)
    assert [s.seconds for s in starts] == [100.0, 130.0, 175.0]
    assert not any(s.bound for s in starts)
    assert starts[0].source == "job 3's time left"
    assert starts[2].source == "job 3's time left plus the estimated durations of jobs 4, 5 ahead"


def test_a_free_rig_starts_the_first_queued_job_now() -> None:
    starts = start_estimates(0.0, False, "", [QueuedRun(1, 20.0), QueuedRun(2, 5.0)])
    assert [s.seconds for s in starts] == [0.0, 20.0]
    assert starts[1].source == "the estimated durations of job 1 ahead"


def test_an_unknown_rig_free_time_leaves_every_start_unknown_and_says_why() -> None:
    starts = start_estimates(None, False, "waits for job 3 (suspended until its device "
                             "answers)", [QueuedRun(4, 30.0), QueuedRun(5, 45.0)])
    assert [s.seconds for s in starts] == [None, None]
    assert all(s.source.startswith("not known: waits for job 3 (suspended") for s in starts)


def test_a_job_without_an_estimate_leaves_the_jobs_behind_it_unknown() -> None:
    starts = start_estimates(10.0, False, "job 1's time left",
                             [QueuedRun(2, None), QueuedRun(3, 45.0), QueuedRun(4, 5.0)])
    assert [s.seconds for s in starts] == [10.0, None, None]
    assert starts[2].source == "not known: job 2 ahead of it has no duration estimate"


def test_an_adaptive_job_ahead_makes_the_later_starts_bounds() -> None:
    starts = start_estimates(10.0, False, "job 1's time left",
                             [QueuedRun(2, 60.0, bound=True), QueuedRun(3, 5.0)])
    assert [s.bound for s in starts] == [False, True]
    assert "upper bound" in starts[1].source and "upper bound" not in starts[0].source
    assert start_estimates(10.0, True, "job 1's time left", [QueuedRun(2, 5.0)])[0].bound
