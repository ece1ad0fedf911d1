"""The time left over HTTP. While a job finishes: counted from the finishing's start (the
switch from loading the basis to reconstructing adds no time back), and no "0 s left" while a
finishing runs past its estimate (the first scan's ETA reached 0 s seconds before its end).
While it measures: a pause does not count as measuring time."""

from __future__ import annotations

import itertools
import time
from typing import Any

import pytest

from gonio.timeleft import FINISHING_FALLBACK_S
from tests.system.api.conftest import SLOW_BASIS_S, Daemon
from tests.system.api.test_scan_flow import ENDED, wait_state

pytestmark = [pytest.mark.system, pytest.mark.timeout(300)]

PLAN = {"kind": "uniform", "specimen": "slow finish", "rotations": 2,
        "exposure": {"exposure_s": 0.005}}


def finishing_timeline(daemon: Daemon) -> list[dict[str, Any]]:
    """Submit ``PLAN`` and poll its detail every 0.1 s until it ends; the polls made while
    it was reconstructing, each with its time since the first of them (``t``)."""
    with daemon.client() as c:
        job = c.post("/api/v1/jobs", params={"accept_uncalibrated": "true"},
                     json={"plan": PLAN}).json()["id"]
        polls: list[dict[str, Any]] = []
        t0 = None
        deadline = time.monotonic() + 240
        while (d := c.get(f"/api/v1/jobs/{job}").json())["state"] not in (
                "completed", "failed", "aborted"):
            assert time.monotonic() < deadline, "the scan did not end"
            if d["state"] == "reconstructing":
                t0 = time.monotonic() if t0 is None else t0
                polls.append({**d, "t": time.monotonic() - t0})
            time.sleep(0.1)
        assert d["state"] == "completed", d
    return polls


def test_time_left_while_finishing_counts_down_once_and_is_unknown_past_its_estimate(
    slow_basis_daemon: Daemon,
) -> None:
    polls = finishing_timeline(slow_basis_daemon)
    assert polls and polls[-1]["t"] > SLOW_BASIS_S - 1, [p["t"] for p in polls]
    # No finished scan on this daemon: the estimate is the measured default.
    assert {p["reconstruction_s"] for p in polls} == {FINISHING_FALLBACK_S}
    lefts = [(p["t"], p["time_left_s"], p["activity"]) for p in polls]
    known = [x for x in lefts if x[1] is not None]
    assert known, lefts
    # Counted down from the finishing's start: it never goes up (the basis loading and the
    # reconstruction are one finishing), and is never 0 s while the job is not done.
    for (_, a, _), (_, b, _) in itertools.pairwise(known):
        assert b <= a + 0.3, lefts
    assert all(left > 0 for _, left, _ in known), lefts
    # Past the estimate (6 s) the basis still loads (9 s): the time left is unknown, null.
    late = [x for x in lefts if x[0] > FINISHING_FALLBACK_S + 1.0]
    assert late and all(left is None for _, left, _ in late), lefts


def test_the_measuring_eta_stands_still_while_paused_and_goes_on_after_resume(
    daemon: Daemon, no_export_fits: None,
) -> None:
    """After a pause the ETA counted the paused time as measuring: resumed after 5 s, it read
    5 s less than when it paused (0 s after a long pause) until the next checkpoint."""
    # About 1.5 s per angle at the test daemon's time scale: a window after the resume
    # before the next checkpoint.
    slow = {**PLAN, "specimen": "paused a while", "rotations": 24,
            "exposure": {"exposure_s": 0.05, "averages": 10}}
    with daemon.client() as c:
        job = c.post("/api/v1/jobs", params={"accept_uncalibrated": "true"},
                     json={"plan": slow}).json()["id"]
        try:
            deadline = time.monotonic() + 120
            while c.get(f"/api/v1/jobs/{job}").json()["done_angles"] < 2:
                assert time.monotonic() < deadline, "the scan did not measure"
                time.sleep(0.1)
            assert c.post(f"/api/v1/jobs/{job}/pause").status_code == 200
            while (d := c.get(f"/api/v1/jobs/{job}").json())["state"] != "paused":
                assert time.monotonic() < deadline, "the scan did not pause"
                time.sleep(0.1)
            paused_eta = d["eta_s"]
            assert paused_eta is not None and paused_eta > 5
            time.sleep(5.0)
            # Frozen: 5 s of counting down would show. (Not to the bit: on a loaded machine the
            # engine may take the pause a moment after the store records it, and the frozen
            # value then moves by milliseconds: 36.550 -> 36.554 in one full run.)
            assert c.get(f"/api/v1/jobs/{job}").json()["eta_s"] == pytest.approx(
                paused_eta, abs=0.5)
            assert c.post(f"/api/v1/jobs/{job}/resume").status_code == 200
            resumed = c.get(f"/api/v1/jobs/{job}").json()
            assert resumed["state"] == "running" and resumed["done_angles"] == d["done_angles"]
            # Counted on from the paused value, not from the checkpoint before the pause.
            assert resumed["eta_s"] == pytest.approx(paused_eta, abs=1.0), (paused_eta, resumed)
        finally:
            c.post(f"/api/v1/jobs/{job}/abort")
            wait_state(c, job, ENDED, timeout=120)


def test_a_job_has_a_measuring_eta_before_its_first_angle_is_done(
    daemon: Daemon, no_export_fits: None,
) -> None:
    """Until its first checkpoint a running job had no eta_s (and the page no time at all);
    it has the rig's physical estimate from the start, as the dry run times it."""
    slow = {**PLAN, "specimen": "first angle", "rotations": 6,
            "exposure": {"exposure_s": 0.05, "averages": 10}}
    with daemon.client() as c:
        job = c.post("/api/v1/jobs", params={"accept_uncalibrated": "true"},
                     json={"plan": slow}).json()["id"]
        seen: list[dict[str, Any]] = []
        deadline = time.monotonic() + 120
        while (d := c.get(f"/api/v1/jobs/{job}").json())["state"] not in (
                "reconstructing", "completed", "failed", "aborted"):
            assert time.monotonic() < deadline, "the scan did not end"
            if d["state"] == "running" and d["done_angles"] == 0 and d["total_angles"]:
                seen.append(d)
            time.sleep(0.05)
        while c.get(f"/api/v1/jobs/{job}").json()["state"] not in (
                "completed", "failed", "aborted"):
            assert time.monotonic() < deadline, "the scan did not end"
            time.sleep(0.2)
    assert seen, "never saw the job before its first checkpoint"
    assert all(p["eta_s"] is not None and p["time_left_s"] is not None for p in seen), seen[0]
    assert seen[0]["eta_s"] > 0


def test_the_dry_run_times_the_finishing_as_the_last_scans_took_it(
    daemon: Daemon, no_export_fits: None,
) -> None:
    """The dry run timed the measuring alone (about 6 s for the page's default scan, which
    took 28 s to its result); it now gives the finishing too, as docs/api.md defines it:
    the median of the newest three completed scans' measured finishing, else the default's."""
    import statistics

    with daemon.client() as c:
        r = c.post("/api/v1/jobs/dry-run", json={"plan": PLAN}).json()
        jobs = c.get("/api/v1/jobs").json()
        cal = c.post("/api/v1/jobs/dry-run", json={"plan": {
            "kind": "calibration", "reference_albedo": 0.99, "rotations": 4}}).json()
        # Each completed scan's measured finishing, from its detail (the list has no summary).
        done = sorted((j["id"], (c.get(f"/api/v1/jobs/{j['id']}").json().get("result")
                                 or {}).get("seconds"))
                      for j in jobs if j["state"] == "completed" and j["kind"] != "calibration")
    timed = [s for _, s in done if isinstance(s, int | float)][-3:]
    expected = statistics.median(timed) if timed else FINISHING_FALLBACK_S
    assert r["finishing_s"] == pytest.approx(expected), (r, done)
    said = r["finishing_source"]
    assert ("on this job store" in said and "yet" not in said) if timed else (
        "no scan has finished on this job store yet" in said), said
    # Not in the measuring estimate, which stays motion + settling + exposures.
    assert r["estimated_s"] == pytest.approx(r["motion_s"] + r["settle_s"] + r["exposure_s"])
    # A calibration reconstructs nothing: no finishing.
    assert cal["finishing_s"] is None and cal["finishing_source"] is None
