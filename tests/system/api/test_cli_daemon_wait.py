"""``gonio scan --daemon URL --no-wait`` and ``gonio jobs --daemon URL wait ID [-o FILE]``.

A lab that queued a scan on the daemon with ``gonio scan --daemon`` had to keep that terminal
open until the scan ended: closed, interrupted or cut off by a daemon restart, nothing on the
command line followed the job again or fetched its result (the messages named raw API URLs).
``--no-wait`` queues and returns, printing the ``jobs wait`` command; ``jobs wait`` follows the
job and fetches its result as ``gonio scan --daemon`` does (one function does both).
"""

from __future__ import annotations

import itertools
import re
import shlex
import threading
import time
import types
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest

from gonio.cli import daemon_jobs, main
from gonio.cli.scan_report import scan_summary
from gonio.results import read_result
from tests.system.api.conftest import Daemon, export_fits_off

pytestmark = pytest.mark.timeout(240)

FAST = {"exposure_s": 0.02, "light_settle_s": 0.0}
QUICK = ["--rotations", "4", "--exposure", "0.02", "--light-settle", "0"]


def _state(c: httpx.Client, job: int) -> str:
    return str(c.get(f"/api/v1/jobs/{job}").json()["state"])


def _until(predicate: Any, what: str, timeout: float = 120.0) -> None:
    deadline = time.monotonic() + timeout
    while not predicate():
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        time.sleep(0.1)


def _submit(c: httpx.Client, rotations: int, specimen: str = "felt") -> int:
    r = c.post("/api/v1/jobs", json={"plan": {"kind": "uniform", "rotations": rotations,
                                              "specimen": specimen, "exposure": FAST}})
    assert r.status_code == 201, r.text
    return int(r.json()["id"])


@pytest.fixture
def held(daemon: Daemon) -> Iterator[httpx.Client]:
    """The daemon's queue held (nothing starts) while the test runs; released after it, with
    whatever the test left queued cancelled."""
    with daemon.client() as c:
        assert c.post("/api/v1/rig/halt").status_code == 200
        try:
            yield c
        finally:
            for job in (j["id"] for j in c.get("/api/v1/jobs", params={"state": "queued"}).json()):
                c.post(f"/api/v1/jobs/{job}/cancel")
            c.post("/api/v1/rig/release")


def test_no_wait_queues_and_returns_and_its_command_fetches_the_result(
    daemon: Daemon, tmp_path: Path, capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch, no_export_fits: None,
) -> None:
    monkeypatch.chdir(tmp_path)  # the suggested result file is relative to where it is run
    with daemon.client() as c:
        assert c.post("/api/v1/rig/halt").status_code == 200  # nothing starts: it stays queued
        try:
            argv = ["scan", "--daemon", daemon.url, "--api-key", daemon.key, *QUICK,
                    "--specimen", "felt", "--no-wait"]  # no -o: optional with --no-wait
            assert main(argv) == 0
            out = capsys.readouterr().out
            job = max(j["id"] for j in c.get("/api/v1/jobs").json())
            # It returned with the job queued, not run.
            assert _state(c, job) == "queued"
            command = f"gonio jobs --daemon {daemon.url} wait {job} -o {tmp_path / 'felt.h5'}"
            assert out.splitlines() == [
                f"job {job} queued on {daemon.url}; follow it and fetch its result with:",
                f"  {command}"]
        finally:
            c.post("/api/v1/rig/release")
        # The printed command, as printed (it names no key: reads need none here), follows the
        # job to its end and fetches its result.
        words = shlex.split(command)
        assert words[0] == "gonio"
        assert main([*words[1:], "--no-progress"]) == 0
        printed = capsys.readouterr().out
        detail = c.get(f"/api/v1/jobs/{job}").json()
    assert detail["state"] == "completed"
    res = read_result(tmp_path / "felt.h5")
    assert res.attrs["job_id"] == job and res.attrs["specimen"] == "felt"
    assert res.samples.values.shape[:2] == (12, 4)  # 12 pairs x 4 stage angles
    # The summary gonio scan --daemon prints, word for word.
    lines = scan_summary(job, detail["result"], tmp_path / "felt.h5",
                         f"the daemon keeps it: {daemon.url}/api/v1/jobs/{job}/result")
    assert printed.splitlines() == [line for line, to_err in lines if not to_err]


def test_no_wait_with_output_names_that_file(
    daemon: Daemon, held: httpx.Client, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "sub dir" / "felt.h5"  # a space: the command quotes it
    assert main(["scan", "--daemon", daemon.url, "--api-key", daemon.key, *QUICK,
                 "--no-wait", "-o", str(out)]) == 0
    printed = capsys.readouterr().out
    job = max(j["id"] for j in held.get("/api/v1/jobs").json())
    assert held.get(f"/api/v1/jobs/{job}").json()["specimen"] == "felt"  # named after -o
    assert f"wait {job} -o '{out}'" in printed, printed
    assert not out.exists()  # nothing fetched yet


def test_wait_on_a_completed_job_fetches_it_at_once(
    daemon: Daemon, tmp_path: Path, capsys: pytest.CaptureFixture[str], no_export_fits: None
) -> None:
    with daemon.client() as c:
        job = _submit(c, 4, "linen")
        _until(lambda: _state(c, job) == "completed", "the job to complete")
        detail = c.get(f"/api/v1/jobs/{job}").json()
    base = ["jobs", "--daemon", daemon.url, "wait", str(job), "--no-progress"]
    out = tmp_path / "linen.h5"
    t0 = time.monotonic()
    assert main([*base, "-o", str(out)]) == 0
    assert time.monotonic() - t0 < 10  # one poll and the fetch, no waiting
    assert read_result(out).attrs["job_id"] == job
    assert capsys.readouterr().out.startswith(f"job {job} completed: ")
    # Without -o: the summary, and where the daemon keeps the result; nothing written.
    assert main(base) == 0
    first = capsys.readouterr().out.splitlines()[0]
    kept = (f"not fetched (the daemon keeps it: {daemon.url}/api/v1/jobs/{job}/result; "
            f"'gonio jobs --daemon {daemon.url} wait {job} -o FILE' fetches it)")
    assert first == scan_summary(job, detail["result"], None, kept)[0][0]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["linen.h5"]
    # With the progress bar on: a job that has ended gets none (it drew a full bar at
    # millions of angles per second, after the summary).
    assert main(["jobs", "--daemon", daemon.url, "wait", str(job)]) == 0
    said = capsys.readouterr()
    assert said.out.startswith(f"job {job} completed: ")
    assert "angle/s" not in said.err and "%|" not in said.err, said.err
    # Ctrl-C while the result is fetched: the job is done and nothing "goes on in the
    # daemon" (it said so); the file is not written, and the same command fetches it.
    def cut(*args: object, **kwargs: object) -> None:
        raise KeyboardInterrupt

    again = tmp_path / "again.h5"
    with pytest.MonkeyPatch.context() as m:
        m.setattr(daemon_jobs, "_fetch_result", cut)
        assert main([*base, "-o", str(again)]) == 130
    err = capsys.readouterr().err
    assert f"stopped fetching; job {job} is completed" in err and "goes on" not in err, err
    assert f"wait {job} -o {again}" in err, err
    assert not again.exists()
    # A file that appears at -o while the job is followed (checked free at the start) is not
    # replaced: the daemon keeps the result, and the command that fetches it says --overwrite.
    checked = daemon_jobs.check_output_path

    def then_appears(path: Path, *args: Any, **kwargs: Any) -> None:
        checked(path, *args, **kwargs)
        path.write_bytes(b"another scan's result")

    with pytest.MonkeyPatch.context() as m:
        m.setattr(daemon_jobs, "check_output_path", then_appears)
        assert main([*base, "-o", str(again)]) == 2
    err = capsys.readouterr().err
    assert again.read_bytes() == b"another scan's result"
    assert f"job {job} completed, but {again} appeared while it was measured" in err, err
    assert f"wait {job} -o {again} --overwrite, or to another -o" in err, err
    # `jobs --daemon URL show` says what the job measured, as `jobs show` on a store does (it
    # printed one line of state), and where to fetch the result.
    assert main(["jobs", "--daemon", daemon.url, "show", str(job)]) == 0
    shown = capsys.readouterr().out
    assert (f"  measured: {detail['result']['n_samples']} samples in "
            in shown), shown
    assert f"predicted_log_rmse {detail['result']['predicted_log_rmse']:.3f}" in shown, shown
    assert f"{daemon.url}/api/v1/jobs/{job}/result (fetch it: " in shown, shown


def test_wait_on_a_cancelled_job_says_so_and_exits_1(
    daemon: Daemon, held: httpx.Client, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    job = _submit(held, 4)
    assert held.post(f"/api/v1/jobs/{job}/cancel").status_code == 200
    out = tmp_path / "felt.h5"
    assert main(["jobs", "--daemon", daemon.url, "wait", str(job), "--no-progress",
                 "-o", str(out)]) == 1
    assert f"job {job} aborted: cancelled before it started" in capsys.readouterr().err
    assert not out.exists()


def test_wait_follows_a_running_job_to_its_abort(
    daemon: Daemon, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    with daemon.client() as c:
        job = _submit(c, 72)
        rc: list[int] = []
        waiter = threading.Thread(target=lambda: rc.append(main([
            "jobs", "--daemon", daemon.url, "wait", str(job), "--no-progress",
            "-o", str(tmp_path / "felt.h5")])), daemon=True)
        waiter.start()
        _until(lambda: c.get(f"/api/v1/jobs/{job}").json()["done_angles"] >= 1,
               "the first angle")
        assert waiter.is_alive()  # following a running job
        assert c.post(f"/api/v1/jobs/{job}/abort").status_code == 200
        waiter.join(timeout=60)
        reason = c.get(f"/api/v1/jobs/{job}").json()["reason"]
    assert rc == [1]
    assert f"job {job} aborted: {reason}" in capsys.readouterr().err
    assert not (tmp_path / "felt.h5").exists()


def test_ctrl_c_in_scan_through_the_daemon_names_the_wait_command(
    daemon: Daemon, tmp_path: Path, capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # Ctrl-C arrives while the command sleeps between polls (where it spends its time).
    def interrupted(seconds: float) -> None:
        raise KeyboardInterrupt

    monkeypatch.setattr(daemon_jobs, "time", types.SimpleNamespace(sleep=interrupted))
    out = tmp_path / "felt.h5"
    with daemon.client() as c:
        assert c.post("/api/v1/rig/halt").status_code == 200
        try:
            assert main(["scan", "--daemon", daemon.url, "--api-key", daemon.key, *QUICK,
                         "--no-progress", "-o", str(out)]) == 130
            job = max(j["id"] for j in c.get("/api/v1/jobs").json())
            assert _state(c, job) == "queued"  # the job goes on
            err = capsys.readouterr().err
            # Ctrl-C in jobs wait: the same command again, which queues nothing.
            assert main(["jobs", "--daemon", daemon.url, "wait", str(job), "--no-progress",
                         "-o", str(out)]) == 130
            waited = capsys.readouterr().err
        finally:
            for queued in (j["id"] for j in c.get("/api/v1/jobs",
                                                  params={"state": "queued"}).json()):
                c.post(f"/api/v1/jobs/{queued}/cancel")
            c.post("/api/v1/rig/release")
    assert "Do not run this command again" in err, err
    command = f"gonio jobs --daemon {daemon.url} wait {job} -o {out}"
    assert f"fetch its result with: {command}" in err
    assert waited.strip().endswith(f"goes on in the daemon. Follow it and fetch its result "
                                   f"with: {command}"), waited
    assert not out.exists()


@pytest.mark.timeout(60)  # without the check it would wait on a held queue for ever
def test_wait_checks_the_output_before_it_waits(
    daemon: Daemon, held: httpx.Client, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    job = _submit(held, 4)  # held: waiting on it would not end
    blocker = tmp_path / "a file"
    blocker.write_text("")
    assert main(["jobs", "--daemon", daemon.url, "wait", str(job),
                 "-o", str(blocker / "felt.h5")]) == 2
    err = capsys.readouterr().err
    assert f"cannot write into {blocker}" in err and "nothing was fetched" in err, err
    # An existing result file is refused too (it was replaced when the job ended), still
    # before the wait, and left as it was.
    old = tmp_path / "felt.h5"
    old.write_bytes(b"yesterday's result")
    assert main(["jobs", "--daemon", daemon.url, "wait", str(job), "-o", str(old)]) == 2
    err = capsys.readouterr().err
    assert f"{old} already exists" in err and "--overwrite" in err, err
    assert "nothing was fetched" in err and "--specimen" not in err, err  # wait names none
    # A dry run through the daemon writes no result: it needs no -o (it was refused without).
    assert main(["scan", "--daemon", daemon.url, "--api-key", daemon.key, "--specimen", "felt",
                 "--dry-run"]) == 0
    assert "nothing moves" in capsys.readouterr().out
    assert old.read_bytes() == b"yesterday's result"


@pytest.mark.parametrize(
    ("argv", "words"),
    [
        (["jobs", "--daemon", "{url}", "wait"], "jobs wait needs a job id, e.g. 'gonio jobs "
         "--daemon {url} wait 3'"),
        (["jobs", "wait", "3"], "give its address, e.g. 'gonio jobs --daemon "
         "http://127.0.0.1:8600 wait 3 -o FILE'"),
        (["jobs", "--daemon", "{url}", "show", "1", "-o", "x.h5"],
         "-o, --overwrite and --no-progress go with wait"),
        (["jobs", "--daemon", "{url}", "wait", "1", "--json"], "show 1 --json"),
        (["jobs", "--daemon", "{url}", "wait", "999999"], "refused"),
        (["scan", "--sim", "--no-wait", "-o", "x.h5"], "--no-wait goes with --daemon URL"),
        (["scan", "--daemon", "{url}", "--no-wait", "--dry-run"], "give one of them"),
        (["scan", "--daemon", "{url}", "--rotations", "4"],
         "the result file is required: -o/--output FILE.h5, e.g. -o felt.h5 (or --no-wait"),
        (["scan", "--sim", "--rotations", "4"], "the result file is required: -o/--output"),
    ],
)
def test_bad_usage_is_refused_naming_the_fix(
    daemon: Daemon, capsys: pytest.CaptureFixture[str], argv: list[str], words: str
) -> None:
    with daemon.client() as c:
        n_jobs = len(c.get("/api/v1/jobs").json())
    assert main([a.format(url=daemon.url) for a in argv]) == 2
    err = capsys.readouterr().err
    assert words.format(url=daemon.url) in err, err
    assert "0angle" not in err  # no empty progress bar above the refusal
    if argv == ["scan", "--sim", "--rotations", "4"]:
        assert "--no-wait" not in err  # it goes with --daemon alone
    with daemon.client() as c:
        assert len(c.get("/api/v1/jobs").json()) == n_jobs  # nothing queued


def test_wait_on_a_calibration_job_copies_that_jobs_own_calibration(
    daemon: Daemon, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # The copy beside -o is the calibration the job made, as its result records it: waited
    # for after a later calibration, copying the daemon's calibration in effect would have
    # written that later one under this job's name.
    import json

    scan = ["scan", "--daemon", daemon.url, "--api-key", daemon.key, "--white-reference",
            "0.99", "--rotations", "2", "--exposure", "0.02", "--light-settle", "0",
            "--no-progress"]
    wait = ["jobs", "--daemon", daemon.url, "--no-progress", "wait"]
    before = daemon.sim.place_white_reference()
    try:
        assert main([*scan, "--no-wait", "-o", str(tmp_path / "white.h5")]) == 0
        first = int(capsys.readouterr().out.split()[1])
        assert main([*wait, str(first), "-o", str(tmp_path / "white.h5")]) == 0
        copy = tmp_path / "white.calibration.json"
        assert capsys.readouterr().out == (
            f"job {first} completed: the daemon now applies this calibration to its scans; "
            f"a copy is in {copy}\n")
        made = json.loads(copy.read_text())
        assert made["source"] == f"job {first}: white reference" and made["pairs"]
        # A later calibration replaces it in the daemon (gonio scan --daemon's own path).
        assert main([*scan, "-o", str(tmp_path / "later.h5")]) == 0
        with daemon.client() as c:
            now = c.get("/api/v1/calibration").json()["source"]
        assert now != made["source"] and now.startswith("job ")
        assert json.loads((tmp_path / "later.calibration.json").read_text())["source"] == now
        capsys.readouterr()
        assert main([*wait, str(first), "-o", str(tmp_path / "again" / "white.h5")]) == 0
        assert capsys.readouterr().out.startswith(
            f"job {first} completed: the daemon applies another calibration now ({now})")
        assert json.loads((tmp_path / "again" / "white.calibration.json").read_text()) == made
    finally:
        daemon.sim.place_specimen(before.brdf)


def test_wait_on_a_queued_job_says_what_it_waits_for_once_and_when_that_changes(
    daemon: Daemon, no_export_fits: None
) -> None:
    """It showed a bar at 0 and nothing else while the job was queued: held by a halt, behind
    another job. A ``gonio jobs --daemon URL wait`` child (its own process, as a lab runs it)
    says why the job waits, once, and again when that changes."""
    import subprocess

    from tests.system.daemon_proc import GONIO, PROJECT_ROOT, child_env

    with daemon.client() as c:
        assert c.post("/api/v1/rig/halt").status_code == 200
        released = False
        try:
            first = _submit(c, 12, "wool")  # ahead of the followed job
            job = _submit(c, 4, "felt")
            waiting = c.get(f"/api/v1/jobs/{job}").json()["waiting"]
            assert waiting and "the queue is held" in waiting  # the API's own words
            child = subprocess.Popen(
                [*GONIO, "jobs", "--daemon", daemon.url, "wait", str(job), "--no-progress"],
                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=child_env(),
                cwd=PROJECT_ROOT)
            lines: list[str] = []
            assert child.stderr is not None
            reader = threading.Thread(target=lambda: lines.extend(child.stderr or ()),
                                      daemon=True)
            reader.start()
            held = (f"job {job} queued: {waiting}; 1 queued job ahead of it; its start is not "
                    "known until then")
            _until(lambda: any(line.rstrip("\n") == held for line in lines),
                   f"the line saying job {job} is held ({lines})")
            # Several polls while nothing changes: said once all the same.
            _until(lambda: c.get(f"/api/v1/jobs/{job}").json()["state"] == "queued", "a poll")
            time.sleep(3)
            assert c.post("/api/v1/rig/release").status_code == 200
            released = True
            # Not communicate(): it would read standard error too, beside the reader thread,
            # and a line could be split between the two (one run saw a line end in the next
            # one's words). Standard output (the summary) is small: read once the child ends.
            child.wait(timeout=200)
            reader.join(timeout=30)
            assert child.stdout is not None
            out = child.stdout.read()
        finally:
            if not released:
                c.post("/api/v1/rig/release")
        assert child.returncode == 0, "".join(lines)
        assert c.get(f"/api/v1/jobs/{job}").json()["state"] == "completed"
    said = [line.rstrip("\n") for line in lines if line.startswith(f"job {job} queued: ")]
    assert said.count(held) == 1, said
    assert all(a != b for a, b in itertools.pairwise(said)), said  # not every poll
    # Released: it waited for the job ahead of it, which held the rig, with a start estimate
    # (or why there is none yet: a job just started has no time estimate).
    behind = [line for line in said if f"waits for job {first} (" in line]
    assert behind, said
    assert all(re.search(r"; (starts (in about|within) \S+ \S+ \(.+\)|starts next( \(.+\))?"
                         r"|start not known: .+)$", line) for line in behind), behind
    assert said.index(held) < said.index(behind[0])
    assert "queued:" not in out  # said on standard error, beside the bar, not in the summary


def test_wait_says_when_a_suspended_job_goes_on(
    daemon: Daemon, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A job suspended on a silent sensor, followed through the daemon: the terminal says why
    it waits and that the daemon retries, then that it goes on when the sensor answers again
    (after the suspended line nothing said the fault had cleared)."""
    with export_fits_off(daemon), daemon.client() as c:
        job = _submit(c, 4)
        daemon.sim.apply_fault("silence:S2:4")  # wall seconds: the job suspends, then goes on
        code = main(["jobs", "--daemon", daemon.url, "wait", str(job), "--no-progress",
                     "-o", str(tmp_path / "felt.h5")])
    err = capsys.readouterr().err
    assert code == 0, err
    suspended = err.find(f"job {job} suspended: S2")
    retries = err.find("the daemon retries and goes on once it answers (Ctrl-C stops "
                       "following, not the job)")
    resumed = err.find(f"job {job} resumed: the device answers again; measuring goes on")
    assert 0 <= suspended < retries < resumed, err
    assert (tmp_path / "felt.h5").is_file()
