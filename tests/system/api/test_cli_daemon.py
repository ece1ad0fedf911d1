"""``gonio scan --daemon URL``: a scan submitted to the daemon that owns the rig."""

from __future__ import annotations

import json
import time
from pathlib import Path

import httpx
import pytest

from gonio.cli import main
from gonio.cli.scan_report import scan_summary
from gonio.results import read_result
from tests.system.api.conftest import Daemon

pytestmark = pytest.mark.timeout(240)


def test_scan_through_the_daemon_writes_its_result(
    daemon: Daemon, tmp_path: Path, capsys: pytest.CaptureFixture[str], no_export_fits: None
) -> None:
    out = tmp_path / "felt.h5"
    argv = ["scan", "--daemon", daemon.url, "--api-key", daemon.key, "--rotations", "4",
            "--specimen", "felt", "--exposure", "0.02", "--light-settle", "0", "--no-progress",
            "-o", str(out)]
    assert main(argv) == 0
    captured = capsys.readouterr()
    assert "queued on" in captured.err and f"wrote {out}" in captured.out
    res = read_result(out)
    assert res.attrs["specimen"] == "felt"
    assert res.samples.values.shape[:2] == (12, 4)  # 12 pairs x 4 stage angles
    # The job is the daemon's: in its list, with the same readings as the file.
    with daemon.client() as c:
        job = c.get(f"/api/v1/jobs/{res.attrs['job_id']}").json()
    assert job["state"] == "completed" and job["specimen"] == "felt"


def test_scan_through_the_daemon_prints_the_local_scans_summary(
    daemon: Daemon, tmp_path: Path, capsys: pytest.CaptureFixture[str], no_export_fits: None
) -> None:
    # The end-of-scan summary is the one a local 'gonio scan' prints (scan_summary, from the
    # job's stored summary): the headline error's meaning, the calibration the values carry
    # and where the result is. It printed the coverage and interval sentences alone, without
    # the meaning or the calibration, and not where the daemon keeps the result.
    out = tmp_path / "felt.h5"
    argv = ["scan", "--daemon", daemon.url, "--api-key", daemon.key, "--rotations", "4",
            "--specimen", "felt", "--exposure", "0.02", "--light-settle", "0", "--no-progress",
            "-o", str(out)]
    assert main(argv) == 0
    printed = capsys.readouterr().out
    job_id = read_result(out).attrs["job_id"]
    with daemon.client() as c:
        job = c.get(f"/api/v1/jobs/{job_id}").json()
    lines = scan_summary(job_id, job["result"], out,
                         f"the daemon keeps it: {daemon.url}/api/v1/jobs/{job_id}/result")
    assert printed.splitlines() == [line for line, to_err in lines if not to_err]
    assert f"/api/v1/jobs/{job_id}/result" in printed.splitlines()[0]
    # This daemon has no calibration: the summary says so, and what the headline means.
    assert "  calibration: none in effect (values are sensor units" in printed
    assert "\n  predicted_log_rmse: " in printed


def test_scan_dry_run_through_the_daemon_moves_nothing(
    daemon: Daemon, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    before = daemon.sim.motion.position_deg()
    with daemon.client() as c:
        n_jobs = len(c.get("/api/v1/jobs").json())
    argv = ["scan", "--daemon", daemon.url, "--api-key", daemon.key, "--rotations", "6",
            "--dry-run", "-o", str(tmp_path / "x.h5")]
    assert main([*argv, "--json"]) == 0
    plan = json.loads(capsys.readouterr().out)
    assert len(plan["positions_deg"]) == 6
    assert main(argv) == 0  # the short summary a person reads, as without --daemon
    assert "stage angles: 6" in capsys.readouterr().out
    assert daemon.sim.motion.position_deg() == pytest.approx(before, abs=1e-6)
    with daemon.client() as c:
        assert len(c.get("/api/v1/jobs").json()) == n_jobs


@pytest.mark.parametrize(
    ("extra", "words"),
    [
        (["--db", "x.sqlite"], "--db does not apply with --daemon"),
        (["--data-dir", "d"], "--data-dir does not apply with --daemon"),
        (["--calibration", "c.json"], "--calibration does not apply with --daemon"),
        (["--rotations", "0"], "rotations"),
    ],
)
def test_scan_through_the_daemon_refuses_bad_requests(
    daemon: Daemon, tmp_path: Path, capsys: pytest.CaptureFixture[str],
    extra: list[str], words: str,
) -> None:
    out = tmp_path / "x.h5"
    try:
        code = main(["scan", "--daemon", daemon.url, "--api-key", daemon.key, *extra,
                     "-o", str(out)])
    except SystemExit as exc:  # a flag of the wrong type or range is refused by argparse
        code = exc.code
    assert code == 2
    assert words in capsys.readouterr().err
    assert not out.exists()


def test_scan_through_the_daemon_no_wait_json_gives_the_job(
    daemon: Daemon, tmp_path: Path, capsys: pytest.CaptureFixture[str], no_export_fits: None
) -> None:
    """A script queueing jobs had to parse "job 13 queued on ..." for the id ('--json goes
    with --dry-run'); with --no-wait --json it gets the daemon's answer, the job's row."""
    code = main(["scan", "--daemon", daemon.url, "--api-key", daemon.key, "--no-wait",
                 "--json", "--rotations", "2", "--specimen", "scripted"])
    assert code == 0
    row = json.loads(capsys.readouterr().out)
    with daemon.client() as c:
        shown = c.get(f"/api/v1/jobs/{row['id']}").json()
    assert shown["specimen"] == row["specimen"] == "scripted", (shown, row)
    # Followed (no --no-wait), the scan prints its summary: --json is refused, saying why.
    code = main(["scan", "--daemon", daemon.url, "--api-key", daemon.key, "--json",
                 "--rotations", "2", "-o", str(tmp_path / "x.h5")])
    assert code == 2
    assert "--json goes with --dry-run or --no-wait" in capsys.readouterr().err


def test_jobs_through_the_daemon_reorder_cancel_and_abort(
    daemon: Daemon, tmp_path: Path, capsys: pytest.CaptureFixture[str], no_export_fits: None
) -> None:
    # A lab whose daemon owns the job store could not cancel, reorder or abort a job from the
    # command line: 'gonio jobs' had no cancel or reorder, and its abort on the daemon's store
    # is refused (two programs must not run jobs from one store) with "use its API".
    # Through --daemon they act on the daemon's queue; the daemon's own answers are the check.
    fast = {"exposure_s": 0.02, "light_settle_s": 0.0}
    base = ["jobs", "--daemon", daemon.url, "--api-key", daemon.key]
    with daemon.client() as c:
        ids = [c.post("/api/v1/jobs", json={"plan": {"kind": "uniform", "rotations": r,
                                                     "exposure": fast}}).json()["id"]
               for r in (72, 4, 4)]
        running, first, second = ids
        deadline = time.monotonic() + 60
        while c.get(f"/api/v1/jobs/{running}").json()["state"] != "running":
            assert time.monotonic() < deadline, "the first job never started"
            time.sleep(0.1)
        assert main([*base, "reorder", str(second), "--priority", "5"]) == 0
        assert c.get(f"/api/v1/jobs/{second}").json()["priority"] == 5
        assert main([*base, "cancel", str(first)]) == 0
        cancelled = c.get(f"/api/v1/jobs/{first}").json()
        assert cancelled["state"] == "aborted" and "cancelled" in cancelled["reason"]
        out = capsys.readouterr().out
        assert f"job {second} reordered: priority 5" in out and f"job {first} cancelled" in out
        # Where it now stands (it said the priority alone): ahead of the job it passed.
        assert f"job {second} reordered: priority 5, state queued, next in the queue" in out, out
        # Cancel is for a queued job: a running one's refusal says how to stop it.
        assert main([*base, "cancel", str(running)]) == 2
        assert f"jobs --daemon {daemon.url} abort {running}" in capsys.readouterr().err
        assert main([*base, "abort", str(running)]) == 0
        deadline = time.monotonic() + 60
        while c.get(f"/api/v1/jobs/{running}").json()["state"] != "aborted":
            assert time.monotonic() < deadline, "the abort was not honoured"
            time.sleep(0.1)
        assert main([*base, "abort", str(second)]) == 0  # queued or running: ends it
    # Without --daemon, cancel says where the queue is.
    assert main(["jobs", "cancel", "3"]) == 2
    assert "gonio jobs --daemon http://127.0.0.1:8600 cancel 3" in capsys.readouterr().err


def test_jobs_through_the_daemon_pause_resume_remove_halt_and_release(
    daemon: Daemon, capsys: pytest.CaptureFixture[str], no_export_fits: None
) -> None:
    """gonio's own words told a shell user to resume a paused job or release a held queue
    ("the page's resume, or POST /api/v1/jobs/5/resume"; "release on the lab page, or POST
    /api/v1/rig/release"), and 'gonio jobs' had no such action ("invalid choice: 'pause'").
    Through --daemon it now pauses, resumes, removes, halts and releases; the daemon's own
    answers (GET /api/v1/jobs/ID, GET /api/v1/rig) are the check."""
    fast = {"exposure_s": 0.02, "light_settle_s": 0.0}
    base = ["jobs", "--daemon", daemon.url, "--api-key", daemon.key]

    def state(c: httpx.Client, job: int) -> str:
        return str(c.get(f"/api/v1/jobs/{job}").json()["state"])

    def until(c: httpx.Client, job: int, wanted: str) -> None:
        deadline = time.monotonic() + 120
        while state(c, job) != wanted:
            assert time.monotonic() < deadline, f"job {job} never became {wanted}"
            time.sleep(0.1)

    with daemon.client() as c:
        running, queued = (c.post("/api/v1/jobs", json={"plan": {
            "kind": "uniform", "rotations": r, "exposure": fast}}).json()["id"] for r in (72, 4))
        until(c, running, "running")
        assert main([*base, "pause", str(running)]) == 0
        until(c, running, "paused")
        assert f"job {running}: pause asked" in capsys.readouterr().out
        assert main([*base, "resume", str(running)]) == 0
        until(c, running, "running")
        assert f"job {running} resumed" in capsys.readouterr().out
        # The emergency halt holds the queue: the queued job says so, and release lifts it.
        assert main([*base, "halt"]) == 0
        until(c, running, "halted")
        assert f"'gonio jobs --daemon {daemon.url} release'" in capsys.readouterr().out
        waiting = c.get(f"/api/v1/jobs/{queued}").json()["waiting"]
        assert "gonio jobs --daemon URL release" in waiting, waiting
        # A queued job removed is gone from the daemon (404), its readings with it.
        assert main([*base, "remove", str(queued)]) == 0
        assert c.get(f"/api/v1/jobs/{queued}").status_code == 404
        assert f"job {queued} removed" in capsys.readouterr().out
        # With --json the answer is JSON too (the API's 204 has no body of its own).
        extra = c.post("/api/v1/jobs", json={"plan": {"kind": "uniform", "rotations": 4,
                                                      "exposure": fast}}).json()["id"]
        assert main([*base, "remove", str(extra), "--json"]) == 0
        assert json.loads(capsys.readouterr().out) == {"id": extra, "removed": True}
        assert c.get(f"/api/v1/jobs/{extra}").status_code == 404
        assert main([*base, "release"]) == 0
        assert c.get("/api/v1/rig").json()["queue_held"] is None, \
            c.get("/api/v1/rig").json()["queue_held"]
        # halt and release act on the queue: a job id is refused, naming the command.
        assert main([*base, "release", "3"]) == 2
        assert f"'gonio jobs --daemon {daemon.url} release'" in capsys.readouterr().err
    # Without --daemon, they say where the daemon's queue is.
    assert main(["jobs", "halt"]) == 2
    assert "gonio jobs --daemon http://127.0.0.1:8600 halt'" in capsys.readouterr().err
