"""Decisions that must outlive the daemon: queue holds and the maintenance lock, across kill -9.

A daemon child process drives the simulated rig (run in this test process) with the real
drivers; it is killed with SIGKILL (no shutdown code runs) and started again on the same data
directory, as systemd would after a crash.
"""

from __future__ import annotations

import re
import signal
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from gonio.drivers.factory import build_rig
from gonio.plans.models import CalibrationPlan, ExposureSettings
from gonio.rigdescription import RigDescription
from gonio.sim.rig import SimRig, SimRigOptions, start_sim_rig
from gonio.store import JobStore
from tests.system.daemon_proc import DaemonProcess, start_daemon, wait_for

pytestmark = [pytest.mark.system, pytest.mark.timeout(300)]

FAST = {"exposure_s": 0.02, "light_settle_s": 0.0}
NOTHING_STARTS_S = 2.0
"""How long a held queue is watched for a job that should not start (a negative check: under
load it can only miss a wrong start, never fail a correct daemon)."""


@pytest.fixture
def sim(tmp_path: Path) -> Iterator[SimRig]:
    with start_sim_rig(SimRigOptions(time_scale=10.0, settle_s=0.0,
                                     config_path=tmp_path / "rig.toml")) as s:
        s.place_white_reference()  # for the calibration jobs (no basis needed)
        yield s


def _serve(sim: SimRig, data: Path) -> DaemonProcess:
    return start_daemon(["--no-export-fits",
                         "--rig", str(sim.config_path), "--data-dir", str(data), "--port", "0"])


def _state(c: Any, job: int) -> str:
    return str(c.get(f"/api/v1/jobs/{job}").json()["state"])


def _submit(c: Any, plan: dict[str, Any]) -> int:
    r = c.post("/api/v1/jobs", json={"plan": plan})
    assert r.status_code == 201, r.text
    return int(r.json()["id"])


def test_halt_hold_and_maintenance_lock_survive_kill_9(sim: SimRig, tmp_path: Path) -> None:
    data = tmp_path / "data"
    first = _serve(sim, data)
    try:
        with first.client() as c:
            long_job = _submit(c, {"kind": "uniform", "rotations": 36, "exposure": FAST})
            wait_for(lambda: c.get(f"/api/v1/jobs/{long_job}").json()["done_angles"] >= 1,
                     what="the first angle")
            assert c.post("/api/v1/rig/halt").status_code == 200
            wait_for(lambda: _state(c, long_job) == "halted", what="the halt")
            waiting = _submit(c, {"kind": "calibration", "reference_albedo": 0.99,
                                  "rotations": 2, "exposure": FAST})
    finally:
        first.stop(signal.SIGKILL)

    second = _serve(sim, data)
    try:
        with second.client() as c:
            assert c.get("/api/v1/rig").json()["queue_held"] == "emergency halt"
            time.sleep(NOTHING_STARTS_S)
            assert _state(c, waiting) == "queued"
            r = c.put("/api/v1/maintenance", json={"reason": "swapping lamp L2"})
            assert r.status_code == 200, r.text
    finally:
        second.stop(signal.SIGKILL)

    third = _serve(sim, data)
    try:
        with third.client() as c:
            lock = c.get("/api/v1/maintenance").json()
            assert lock["locked"] and lock["reason"] == "swapping lamp L2" and lock["by"] == "t"
            # Nothing new starts on the rig, whoever asks.
            design = c.post("/api/v1/design", json={"pairs": 3, "time_limit_s": 1})
            assert design.status_code == 423, design.text
            plan = {"kind": "uniform", "rotations": 2, "exposure": FAST}
            assert c.post("/api/v1/jobs", json={"plan": plan}).status_code == 423
            assert c.post("/api/v1/rig/stage", json={"action": "move", "angle_deg": 5}
                          ).status_code == 423
            assert c.delete("/api/v1/maintenance").status_code == 200
            # The halt's hold is still there after the lock is gone: only a release ends it.
            assert c.get("/api/v1/rig").json()["queue_held"] == "emergency halt"
            assert _state(c, waiting) == "queued"
            assert c.post("/api/v1/rig/release").status_code == 200
            wait_for(lambda: _state(c, waiting) == "completed", what="the released job")
            assert _state(c, long_job) == "halted"
    finally:
        third.stop()


def test_a_lock_set_from_a_shell_stops_queued_and_interrupted_jobs(
    sim: SimRig, tmp_path: Path
) -> None:
    data = tmp_path / "data"
    data.mkdir()
    # Jobs in the store before the daemon starts: one left running by a crash, one queued.
    store = JobStore(data / "gonio.sqlite")
    desc = RigDescription.from_rig(build_rig(sim.config)).model_dump(mode="json")
    plan = CalibrationPlan(reference_albedo=0.99, rotations=2,
                           exposure=ExposureSettings(**FAST)).model_dump(mode="json")
    interrupted = store.create_job(kind="calibration", specimen="w", plan=plan, rig=desc).id
    store.set_state(interrupted, "running")
    queued = store.create_job(kind="calibration", specimen="w", plan=plan, rig=desc).id
    store.close()
    (data / "MAINTENANCE").write_text("rewiring the sensor bus\n")
    position = sim.motion.position_deg()

    daemon = _serve(sim, data)
    try:
        with daemon.client() as c:
            assert c.get("/api/v1/rig").json()["queue_held"] == (
                "maintenance lock: rewiring the sensor bus")
            time.sleep(NOTHING_STARTS_S)
            assert _state(c, queued) == "queued"
            assert c.get(f"/api/v1/jobs/{interrupted}").json()["done_angles"] == 0
            assert sim.motion.position_deg() == position  # the stage never moved
            (data / "MAINTENANCE").unlink()  # released from the shell too
            wait_for(lambda: _state(c, queued) == "completed", what="the queued job")
            assert _state(c, interrupted) == "completed"
    finally:
        daemon.stop()


def test_stop_on_failure_hold_survives_kill_9(sim: SimRig, tmp_path: Path) -> None:
    data = tmp_path / "data"
    first = _serve(sim, data)
    try:
        with first.client() as c:
            sim.apply_fault("silence:S1")
            failing = _submit(c, {"kind": "uniform", "rotations": 2, "exposure": FAST,
                                  "stop_queue_on_failure": True,
                                  # A silent device is waited for unless told not to.
                                  "faults": {"max_retries": 0, "retry_delay_s": 0.1,
                                             "wait_for_device_s": 0}})
            wait_for(lambda: _state(c, failing) == "failed", what="the failure")
            sim.clear_faults()
            held = f"job {failing} failed and asked to stop the queue"
            assert c.get("/api/v1/rig").json()["queue_held"] == held
            later = _submit(c, {"kind": "calibration", "reference_albedo": 0.99,
                                "rotations": 2, "exposure": FAST})
    finally:
        first.stop(signal.SIGKILL)
    second = _serve(sim, data)
    try:
        with second.client() as c:
            assert c.get("/api/v1/rig").json()["queue_held"] == held
            time.sleep(NOTHING_STARTS_S)
            assert _state(c, later) == "queued"
            assert c.post("/api/v1/rig/release").status_code == 200
            wait_for(lambda: _state(c, later) == "completed", what="the released job")
    finally:
        second.stop()


def test_scan_through_a_daemon_killed_mid_scan_says_the_job_is_kept(
    sim: SimRig, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # A lab user's `gonio scan --daemon` whose daemon was killed mid-scan printed only "cannot
    # reach the daemon ... is it running?": nothing said the job was stored and would resume,
    # and running the command again queued a second scan of the specimen. It must name the
    # job, say a restarted daemon takes it up and not to run the command again; the restarted
    # daemon then does take it up (the message's claim, checked on the real daemon).
    import threading

    from gonio.cli import main
    from tests.system.daemon_proc import TEST_KEY

    data = tmp_path / "data"
    first = _serve(sim, data)
    rc: list[int] = []
    argv = ["scan", "--daemon", first.url, "--api-key", TEST_KEY, "--rotations", "36",
            "--exposure", "0.02", "--light-settle", "0", "--no-progress",
            "-o", str(tmp_path / "felt.h5")]
    follower = threading.Thread(target=lambda: rc.append(main(argv)), daemon=True)
    try:
        follower.start()
        with first.client() as c:
            wait_for(lambda: any(j["done_angles"] >= 1 for j in c.get("/api/v1/jobs").json()),
                     what="the first angle")
            job = next(j["id"] for j in c.get("/api/v1/jobs").json() if j["kind"] == "uniform")
    finally:
        first.stop(signal.SIGKILL)
    follower.join(timeout=60)
    assert rc == [1]
    err = capsys.readouterr().err
    assert "cannot reach the daemon" in err
    # Its last word on the job: running, or queued when the kill came before its first poll
    # (the queueing answer) -- a busy machine decides which.
    assert re.search(rf"job {job} \(last seen (running|queued), \d+ of 36 angles\)", err), err
    assert "Do not run this command again" in err
    # The command that takes the job up again, not the API's URLs.
    again = f"gonio jobs --daemon {first.url} wait {job} -o {tmp_path / 'felt.h5'}"
    assert f"follow the job and fetch its result with: {again}" in err, err

    second = _serve(sim, data)
    try:
        with second.client() as c:
            wait_for(lambda: c.get(f"/api/v1/jobs/{job}").json()["done_angles"] > 1
                     and _state(c, job) == "running", what="the job taken up again")
            assert len(c.get("/api/v1/jobs").json()) == 1  # and no second scan
            # That command (on the restarted daemon's address: this one listens on another
            # port) follows the job; aborted here, it says so.
            words = again.replace(first.url, second.url).split()
            waiter = threading.Thread(target=lambda: rc.append(main(
                [*words[1:], "--no-progress"])), daemon=True)
            waiter.start()
            time.sleep(1.0)
            assert waiter.is_alive()
            assert c.post(f"/api/v1/jobs/{job}/abort").status_code == 200
            waiter.join(timeout=60)
        assert rc == [1, 1]
        assert f"job {job} aborted: " in capsys.readouterr().err
    finally:
        second.stop(signal.SIGKILL)
