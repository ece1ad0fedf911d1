"""The state of calibration is said wherever a scan's numbers are read, and an uncalibrated
scan of a rig that was calibrated is refused until the user accepts it (issue 27, item 1).

A real daemon on the simulated rig (tests/system/api/conftest.py) on a data directory of its
own, as `gonio serve --rig rig.toml --data-dir ELSEWHERE` would run: the rig's calibration is
in `gonio scan`'s data directory for that rig, not in the daemon's.
"""

from __future__ import annotations

import time
from collections.abc import Iterator

import httpx
import pytest

from gonio.calibration import CALIBRATION_FILE, Calibration, PairCalibration, save_calibration
from gonio.paths import scan_data_dir
from tests.system.api.conftest import Daemon
from tests.system.api.test_scan_flow import ENDED, wait_state

pytestmark = pytest.mark.system

PLAN = {"kind": "uniform", "specimen": "felt", "rotations": 4}


@pytest.fixture
def calibrated_elsewhere(daemon: Daemon) -> Iterator[Calibration]:
    """A white-reference calibration of this rig in its own (gonio scan's) data directory."""
    cfg = daemon.sim.config
    cal = Calibration(
        pairs=tuple(PairCalibration(light=p.light, sensor=p.sensor, factor=(1e-3, 1e-3, 1e-3))
                    for p in cfg.pair_list()),
        reference_albedo=0.99, source="white reference")
    own = scan_data_dir(cfg)
    assert own.resolve() != daemon.data_dir.resolve()
    own.mkdir(parents=True, exist_ok=True)
    save_calibration(cal, own / CALIBRATION_FILE)
    try:
        yield cal
    finally:
        (own / CALIBRATION_FILE).unlink()


def test_check_plan_says_an_uncalibrated_scan_is_in_sensor_units(daemon: Daemon) -> None:
    with daemon.client() as c:
        assert c.get("/api/v1/calibration").json()["source"] == "none"
        r = c.post("/api/v1/jobs/dry-run", json={"plan": PLAN})
        assert r.status_code == 200, r.text
        warnings = r.json()["warnings"]
        assert any(w.startswith("uncalibrated") and "sensor units" in w for w in warnings), \
            warnings
        # A calibration job is what makes a calibration: it gets no such warning.
        cal_plan = {"kind": "calibration", "reference_albedo": 0.99, "rotations": 4}
        r = c.post("/api/v1/jobs/dry-run", json={"plan": cal_plan})
        assert not any("uncalibrated" in w for w in r.json()["warnings"])


def test_check_plan_behind_a_queued_calibration_does_not_say_uncalibrated(
        daemon: Daemon) -> None:
    """`gonio serve --sim` queues a calibration job at start: a plan checked meanwhile is
    calibrated by it and was told "uncalibrated: ... run a calibration job first". At a
    priority above the calibration's it would run first, uncalibrated: that is said, naming
    the calibration job."""
    with daemon.client() as c:
        assert c.get("/api/v1/calibration").json()["source"] == "none"
        assert c.post("/api/v1/rig/halt").status_code == 200  # the queue holds
        try:
            r = c.post("/api/v1/jobs", json={"plan": CAL_PLAN})
            assert r.status_code == 201, r.text
            cal = r.json()["id"]
            r = c.post("/api/v1/jobs/dry-run", json={"plan": PLAN})
            assert r.status_code == 200, r.text
            assert not [w for w in r.json()["warnings"] if "uncalibrated" in w], r.json()
            r = c.post("/api/v1/jobs/dry-run", json={"plan": PLAN, "priority": 1})
            assert r.status_code == 200, r.text
            (w,) = [w for w in r.json()["warnings"] if w.startswith("uncalibrated")]
            assert f"calibration job {cal} is queued at priority 0, below this scan's 1" in w, w
        finally:
            for job in (j["id"] for j in c.get("/api/v1/jobs", params={"state": "queued"}).json()):
                c.post(f"/api/v1/jobs/{job}/cancel")
            c.post("/api/v1/rig/release")


def test_uncalibrated_scan_of_a_calibrated_rig_needs_acceptance(
    daemon: Daemon, calibrated_elsewhere: Calibration
) -> None:
    with daemon.client() as c:
        before = len(c.get("/api/v1/jobs").json())
        r = c.post("/api/v1/jobs", json={"plan": PLAN})
        assert r.status_code == 409, r.text
        detail = r.json()["detail"]
        # It says why (the rig's calibration is in another data directory, named) and what
        # to do; nothing was queued.
        assert str(scan_data_dir(daemon.sim.config)) in detail, detail
        assert "accept_uncalibrated=true" in detail and "calibration job" in detail, detail
        assert len(c.get("/api/v1/jobs").json()) == before
        # Accepted: queued as asked (then cancelled: its readings are not under test).
        r = c.post("/api/v1/jobs", params={"accept_uncalibrated": "true"}, json={"plan": PLAN})
        assert r.status_code == 201, r.text
        job = r.json()["id"]
        c.post(f"/api/v1/jobs/{job}/abort")


def test_an_uncalibrated_rig_needs_no_acceptance(daemon: Daemon) -> None:
    # Never calibrated anywhere (a first session): no refusal, the Check plan's warning says it.
    own = scan_data_dir(daemon.sim.config) / CALIBRATION_FILE
    assert not own.exists()
    with daemon.client() as c:
        r = c.post("/api/v1/jobs", json={"plan": PLAN})
        assert r.status_code == 201, r.text
        job = r.json()["id"]
        c.post(f"/api/v1/jobs/{job}/abort")


def test_a_scan_queued_behind_a_calibration_is_not_moved_ahead_of_it_unasked(
    daemon: Daemon, calibrated_elsewhere: Calibration
) -> None:
    # A scan behind a queued calibration is queued without asking (it is finished with that
    # calibration). Moved ahead of it afterwards (a higher priority, an earlier place, or the
    # calibration moved down), it ran first, uncalibrated, and nobody had been asked.
    cal_plan = {"kind": "calibration", "reference_albedo": 0.99, "rotations": 4}
    with daemon.client() as c:
        assert c.post("/api/v1/rig/halt").status_code == 200  # the queue holds: all stay queued
        try:
            r = c.post("/api/v1/jobs", json={"plan": cal_plan, "priority": 5})
            assert r.status_code == 201, r.text
            cal = r.json()["id"]
            r = c.post("/api/v1/jobs", json={"plan": PLAN})
            assert r.status_code == 201, r.text  # behind the calibration: not asked
            scan = r.json()["id"]

            def first(a: int, b: int) -> bool:
                """Whether the queue takes job a before job b."""
                pos = {j: c.get(f"/api/v1/jobs/{j}").json()["queue_position"] for j in (a, b)}
                return bool(pos[a] < pos[b])

            assert first(cal, scan)
            for job, move in ((scan, {"priority": 10}), (scan, {"position": 0}),
                              (cal, {"priority": -5})):
                r = c.post(f"/api/v1/jobs/{job}/reorder", json=move)
                assert r.status_code == 409, (move, r.text)
                detail = r.json()["detail"]
                assert f"job {scan} would then run before calibration job {cal}" in detail, detail
                assert "uncalibrated" in detail and "accept_uncalibrated=true" in detail, detail
                assert first(cal, scan)  # nothing moved
                assert c.get(f"/api/v1/jobs/{scan}").json()["priority"] == 0
            # Still behind it: moved as asked.
            r = c.post(f"/api/v1/jobs/{scan}/reorder", json={"priority": 5})
            assert r.status_code == 200, r.text
            assert first(cal, scan)
            # Accepted: it runs first, in sensor units, as asked.
            r = c.post(f"/api/v1/jobs/{scan}/reorder", params={"accept_uncalibrated": "true"},
                       json={"priority": 10})
            assert r.status_code == 200, r.text
            assert first(scan, cal)
        finally:
            for job in (j["id"] for j in c.get("/api/v1/jobs", params={"state": "queued"}).json()):
                c.post(f"/api/v1/jobs/{job}/cancel")
            c.post("/api/v1/rig/release")


CAL_PLAN = {"kind": "calibration", "reference_albedo": 0.99, "rotations": 4}


def _queue_behind_a_calibration(c: httpx.Client, **scan_params: str) -> tuple[int, int]:
    """A calibration job and, behind it, a scan of PLAN (the queue held: both stay queued)."""
    r = c.post("/api/v1/jobs", json={"plan": CAL_PLAN, "priority": 5})
    assert r.status_code == 201, r.text
    cal = r.json()["id"]
    r = c.post("/api/v1/jobs", params=scan_params, json={"plan": PLAN})
    assert r.status_code == 201, r.text
    return cal, r.json()["id"]


def test_a_scan_queued_behind_a_calibration_that_never_ran_is_not_measured_uncalibrated(
    daemon: Daemon, calibrated_elsewhere: Calibration
) -> None:
    # Queued without asking because the calibration was to run first; the calibration is then
    # cancelled. The scan used to run anyway, in sensor units, with nobody asked.
    with daemon.client() as c:
        assert c.post("/api/v1/rig/halt").status_code == 200
        try:
            cal, scan = _queue_behind_a_calibration(c)
            assert c.post(f"/api/v1/jobs/{cal}/cancel").status_code == 200
        finally:
            c.post("/api/v1/rig/release")
        job = wait_state(c, scan, ENDED)
        assert job["state"] == "failed", job
        reason = job["reason"]
        assert reason.startswith("not started:"), reason
        # Why (the rig's calibration elsewhere, named), how it came to be queued, what to do.
        assert str(scan_data_dir(daemon.sim.config)) in reason, reason
        assert f"calibration job {cal} was to run before it; that job was cancelled" in reason
        assert "accept_uncalibrated=true" in reason, reason
        # Nothing was measured.
        assert job["done_angles"] == 0, job
        assert c.get(f"/api/v1/jobs/{scan}/readings").json() == []


def test_a_scan_whose_user_accepted_sensor_units_runs_when_the_calibration_does_not(
    daemon: Daemon, calibrated_elsewhere: Calibration
) -> None:
    # Accepted at submission, or when moved ahead of the calibration: either way the
    # acceptance travels with the job to its start.
    with daemon.client() as c:
        assert c.post("/api/v1/rig/halt").status_code == 200
        try:
            cal, accepted = _queue_behind_a_calibration(c, accept_uncalibrated="true")
            r = c.post("/api/v1/jobs", json={"plan": PLAN})
            assert r.status_code == 201, r.text  # behind the calibration: not asked
            moved = r.json()["id"]
            r = c.post(f"/api/v1/jobs/{moved}/reorder", params={"accept_uncalibrated": "true"},
                       json={"priority": 10})
            assert r.status_code == 200, r.text
            assert c.post(f"/api/v1/jobs/{cal}/cancel").status_code == 200
        finally:
            c.post("/api/v1/rig/release")
        for job in (moved, accepted):
            # It leaves the queue and measures (its first angle is enough to tell).
            state = wait_state(c, job, {"running", "failed", "completed"})
            assert state["state"] != "failed", state
            deadline = time.monotonic() + 120
            while c.get(f"/api/v1/jobs/{job}").json()["done_angles"] == 0:
                assert time.monotonic() < deadline, f"job {job} measured nothing"
                time.sleep(0.1)
            assert c.post(f"/api/v1/jobs/{job}/abort").status_code == 200
            wait_state(c, job, ENDED)


def test_a_scan_queued_behind_a_calibration_that_fails_is_not_measured_uncalibrated(
    daemon: Daemon, calibrated_elsewhere: Calibration
) -> None:
    # The calibration runs and fails (the simulated stage holds the specimen, not the white
    # reference): the scan queued behind it unasked fails before anything moves.
    with daemon.client() as c:
        assert c.post("/api/v1/rig/halt").status_code == 200
        try:
            cal, scan = _queue_behind_a_calibration(c)
        finally:
            c.post("/api/v1/rig/release")
        cal_job = wait_state(c, cal, ENDED)
        assert cal_job["state"] == "failed", cal_job
        assert "calibration refused" in cal_job["reason"], cal_job
        job = wait_state(c, scan, ENDED)
        assert job["state"] == "failed", job
        reason = job["reason"]
        assert reason.startswith("not started:"), reason
        assert f"calibration job {cal} was to run before it; that job failed" in reason
        assert "accept_uncalibrated=true" in reason, reason
        assert job["done_angles"] == 0, job
        assert c.get(f"/api/v1/jobs/{scan}/readings").json() == []


def test_gonio_jobs_reorder_ahead_of_a_calibration_asks_for_the_flag(
    daemon: Daemon, calibrated_elsewhere: Calibration, capsys: pytest.CaptureFixture[str]
) -> None:
    # The daemon's 409 named accept_uncalibrated=true, a query parameter the command had no
    # way to send.
    from gonio.cli import main

    base = ["jobs", "--daemon", daemon.url, "--api-key", daemon.key]
    with daemon.client() as c:
        assert c.post("/api/v1/rig/halt").status_code == 200
        try:
            cal, scan = _queue_behind_a_calibration(c)
            assert main([*base, "reorder", str(scan), "--priority", "10"]) == 2
            err = capsys.readouterr().err
            assert f"would then run before calibration job {cal}" in err, err
            assert "--accept-uncalibrated" in err, err
            assert c.get(f"/api/v1/jobs/{scan}").json()["priority"] == 0  # not moved
            assert main([*base, "reorder", str(scan), "--priority", "10",
                         "--accept-uncalibrated"]) == 0
            assert f"job {scan} reordered: priority 10" in capsys.readouterr().out
            assert c.get(f"/api/v1/jobs/{scan}").json()["priority"] == 10
        finally:
            for job in (j["id"] for j in c.get("/api/v1/jobs", params={"state": "queued"}).json()):
                c.post(f"/api/v1/jobs/{job}/cancel")
            c.post("/api/v1/rig/release")
