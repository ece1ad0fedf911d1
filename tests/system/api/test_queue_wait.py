"""Why a queued job does not start, said the same way by the API (``waiting`` in the job list
and detail), the lab page's queue and ``gonio jobs list``: after an emergency halt the queue
was held with no word on the queued job anywhere but the stage chip."""

from __future__ import annotations

import json
import time

import pytest

from gonio.cli import main
from tests.system.api.conftest import Daemon

pytestmark = [pytest.mark.system, pytest.mark.timeout(300)]

PLAN = {"kind": "uniform", "specimen": "after the halt", "rotations": 2,
        "exposure": {"exposure_s": 0.005}}


def test_a_queued_job_under_a_halt_says_why_it_waits_in_the_api_and_gonio_jobs(
    daemon: Daemon, no_export_fits: None, capsys: pytest.CaptureFixture[str],
) -> None:
    with daemon.client() as c:
        assert c.post("/api/v1/rig/halt").status_code == 200
        try:
            job = c.post("/api/v1/jobs", params={"accept_uncalibrated": "true"},
                         json={"plan": PLAN}).json()["id"]
            time.sleep(1.0)  # the worker has looked at the queue
            detail = c.get(f"/api/v1/jobs/{job}").json()
            assert detail["state"] == "queued", detail
            waiting = detail["waiting"]
            assert waiting is not None and "the queue is held (emergency halt)" in waiting
            assert "POST /api/v1/rig/release" in waiting
            listed = {j["id"]: j for j in c.get("/api/v1/jobs").json()}
            assert listed[job]["waiting"] == waiting
            # Only a queued job waits: the others say nothing of it.
            assert all(j["waiting"] is None for j in listed.values() if j["id"] != job)
            # gonio jobs on the daemon's store says the same, in its list and its JSON.
            db = str(daemon.data_dir / "gonio.sqlite")
            assert main(["jobs", "list", "--db", db]) == 0
            line = next(x for x in capsys.readouterr().out.splitlines()
                        if x.split()[:2] == [str(job), "queued"])
            assert line.endswith(f"({waiting})"), line
            assert main(["jobs", "list", "--db", db, "--json"]) == 0
            rows = {r["id"]: r for r in json.loads(capsys.readouterr().out)}
            assert rows[job]["waiting"] == waiting
            # The API's names and values for what a store holds ("done"/"total" there broke a
            # script moved between 'gonio jobs --db' and '--daemon').
            assert {"done_angles", "total_angles", "priority"} <= set(rows[job])
            for key, value in rows[job].items():
                if key in ("done", "total"):  # the old names, kept for scripts
                    assert value == rows[job][f"{key}_angles"]
                    continue
                assert key in listed[job] and listed[job][key] == value, (key, listed[job])
        finally:
            assert c.post("/api/v1/rig/release").status_code == 200
        # Released: nothing holds it any more, and it runs.
        assert c.get(f"/api/v1/jobs/{job}").json()["waiting"] is None
        deadline = time.monotonic() + 120
        while c.get(f"/api/v1/jobs/{job}").json()["state"] != "completed":
            assert time.monotonic() < deadline, "the released job did not complete"
            time.sleep(0.2)


def test_a_queued_job_counts_the_angles_it_will_measure(
    daemon: Daemon, capsys: pytest.CaptureFixture[str],
) -> None:
    """A queued 8-angle scan read "0/0" in the API, on the page's progress and in gonio jobs
    until it started; it reads 0 of 8, and a cancelled one says how many it would have."""
    with daemon.client() as c:
        assert c.post("/api/v1/rig/halt").status_code == 200  # it stays queued
        try:
            job = c.post("/api/v1/jobs", params={"accept_uncalibrated": "true"},
                         json={"plan": {**PLAN, "rotations": 8}}).json()
            assert (job["done_angles"], job["total_angles"]) == (0, 8)
            assert c.get(f"/api/v1/jobs/{job['id']}").json()["total_angles"] == 8
            assert main(["jobs", "list", "--db", str(daemon.data_dir / "gonio.sqlite")]) == 0
            line = next(x for x in capsys.readouterr().out.splitlines()
                        if x.split()[:2] == [str(job["id"]), "queued"])
            assert line.split()[3] == "0/8", line
            assert c.post(f"/api/v1/jobs/{job['id']}/cancel").status_code == 200
            assert c.get(f"/api/v1/jobs/{job['id']}").json()["total_angles"] == 8
        finally:
            assert c.post("/api/v1/rig/release").status_code == 200


def test_gonio_jobs_show_says_what_the_api_says_of_a_queued_job(
    daemon: Daemon, capsys: pytest.CaptureFixture[str],
) -> None:
    """``gonio jobs show`` printed the stored row (no ``waiting``, no queue position): it
    shows the fields of ``GET /api/v1/jobs/{id}``, as JSON with --json and readable without."""
    with daemon.client() as c:
        assert c.post("/api/v1/rig/halt").status_code == 200  # it stays queued
        try:
            job = c.post("/api/v1/jobs", params={"accept_uncalibrated": "true"},
                         json={"plan": {**PLAN, "specimen": "shown"}}).json()["id"]
            time.sleep(1.0)  # the worker has looked at the queue
            api = c.get(f"/api/v1/jobs/{job}").json()
            db = str(daemon.data_dir / "gonio.sqlite")
            assert main(["jobs", "show", str(job), "--db", db, "--json"]) == 0
            shown = json.loads(capsys.readouterr().out)
            assert shown == api  # every field, the same values
            assert api["waiting"] and api["queue_position"] == 0
            assert main(["jobs", "show", str(job), "--db", db]) == 0
            text = capsys.readouterr().out
            assert f"job {job}: uniform 'shown', queued, 0/2 angles" in text
            assert f"waiting: {api['waiting']}" in text
            assert "queue position: 0" in text
        finally:
            assert c.post(f"/api/v1/jobs/{job}/cancel").status_code == 200
            assert c.post("/api/v1/rig/release").status_code == 200
