"""A silent device is waited for under the plan's fault policy, whenever it falls silent.

* At the first connection of the rig (the first job after a start) as mid-scan: the job is
  suspended and resumes when the device answers again, instead of failing at once.
* Across a restart: a job suspended waiting for a device is resumed waiting after the daemon
  stops (as on SIGTERM) and starts again on the same data directory while the device is still
  silent; it is not failed, and its readings stay its own.

Real drivers against the simulated rig, real HTTP on loopback, a real SQLite file.
"""

from __future__ import annotations

import threading
from pathlib import Path
from typing import Any

import pytest

from gonio.service import Event, GonioService
from gonio.sim.rig import SimRigOptions, start_sim_rig
from tests.system.api.test_start_races import PLAN, fresh_daemon, wait_until

pytestmark = [pytest.mark.system, pytest.mark.timeout(300)]

MEASURED = ("reconstructing", "completed")


def _state(c: Any, job: int) -> str:
    return str(c.get(f"/api/v1/jobs/{job}").json()["state"])


def _readings_once(c: Any, job: int, angles: int, pairs: int) -> None:
    r = c.get(f"/api/v1/jobs/{job}/readings")
    assert r.status_code == 200, r.text
    keys = [(x["angle_index"], x["light"], x["sensor"]) for x in r.json()]
    assert len(keys) == len(set(keys)) == angles * pairs


def test_the_first_connection_waits_out_a_silent_sensor(tmp_path: Path, basis: Any) -> None:
    with fresh_daemon(tmp_path / "data", basis) as d, d.client() as c:
        service: GonioService = d.app.state.service
        d.sim.apply_fault("silence:S2:4")  # wall seconds: longer than the retries last
        job = int(c.post("/api/v1/jobs", json={"plan": PLAN}).json()["id"])
        wait_until("the job measured or failed",
                   lambda: _state(c, job) in (*MEASURED, "failed"))
        row = service.store.get_job(job)
        assert row.state.value in MEASURED, row.reason
        events = [e for e in service.store.events_after(0) if e.job_id == job]
        first_progress = next(e.seq for e in events if e.type == "progress")
        suspended = [e for e in events if e.type == "state" and e.data["state"] == "suspended"]
        # Suspended on S2 before the first reading, as a silence mid-scan would be.
        assert suspended and suspended[0].data["device"] == "S2"
        assert suspended[0].seq < first_progress
        assert any(e.type == "recovered" and e.data["device"] == "S2" for e in events)
        _readings_once(c, job, PLAN["rotations"], len(service.desc.pairs))


@pytest.mark.parametrize(("stage", "fault", "device"), [
    ("dynamixel", "silence:S3", "S3"),  # a sensor's cable pulled
    ("zaber", "stage-silent", "stage"),  # the stage's power lost
])
def test_a_restart_while_waiting_for_a_silent_device_keeps_the_job_waiting(
        tmp_path: Path, basis: Any, stage: str, fault: str, device: str) -> None:
    data = tmp_path / "data"
    with start_sim_rig(SimRigOptions(stage=stage, time_scale=10.0, settle_s=0.0)) as sim:
        with fresh_daemon(data, basis, sim) as d, d.client() as c:
            service: GonioService = d.app.state.service
            unplugged = threading.Event()

            def unplug_after_first_angle(ev: Event) -> None:
                if ev.type == "progress" and ev.data["done"] == 1 and not unplugged.is_set():
                    unplugged.set()
                    sim.apply_fault(fault)  # until cleared

            service.add_event_listener(unplug_after_first_angle)
            job = int(c.post("/api/v1/jobs", json={"plan": PLAN}).json()["id"])
            wait_until(f"the job waiting for {device}", lambda: any(
                e.type == "fault" and e.job_id == job and "waiting_s" in e.data
                and e.data["device"] == device for e in service.store.events_after(0)))
            done_before = c.get(f"/api/v1/jobs/{job}").json()["done_angles"]
            assert done_before >= 1
        # The daemon stopped (its lifespan ends as on SIGTERM); the device is still silent.
        with fresh_daemon(data, basis, sim) as d, d.client() as c:
            service = d.app.state.service
            store = service.store
            restart = next(e.seq for e in store.events_after(0)
                           if e.type == "recovered" and e.job_id == job and "state" in e.data)

            def waiting_again_or_failed() -> str | None:
                if _state(c, job) == "failed":
                    return "failed"
                again = [e for e in store.events_after(restart) if e.job_id == job
                         and e.type == "state" and e.data["state"] == "suspended"]
                return "waiting" if again else None

            outcome = wait_until("the resumed job waiting or failed", waiting_again_or_failed)
            assert outcome == "waiting", store.get_job(job).reason
            assert c.get(f"/api/v1/jobs/{job}").json()["done_angles"] == done_before
            sim.clear_faults()  # the device answers again
            wait_until("the job measured", lambda: _state(c, job) in (*MEASURED, "failed"))
            assert _state(c, job) in MEASURED, store.get_job(job).reason
            _readings_once(c, job, PLAN["rotations"], len(service.desc.pairs))
