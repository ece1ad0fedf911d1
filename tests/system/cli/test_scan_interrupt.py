"""Ctrl-C in ``gonio scan`` leaves the job paused (not "running" for ever) and says how to
resume or abort it; running the same command again resumes it (issue 27, item 4)."""

from __future__ import annotations

import signal
import subprocess
from collections.abc import Callable
from pathlib import Path

import pytest

from gonio.cli import main
from gonio.jobstates import JobState
from gonio.sim.rig import SimRigOptions, start_sim_rig
from gonio.store import JobRow, JobStore
from tests.system.daemon_proc import GONIO, PROJECT_ROOT, child_env, gonio, wait_for

pytestmark = [pytest.mark.system, pytest.mark.timeout(900)]


def _default_sigint() -> None:
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _default(sig: signal.Signals) -> None:
    """In the child before it runs: ``sig`` back to its default disposition."""
    signal.signal(sig, signal.SIG_DFL)


def _readings(db: Path) -> int:
    if not db.is_file():
        return 0
    store = JobStore(db, durable=False)
    try:
        jobs = store.list_jobs()
        return len(store.readings(jobs[0].id)) if jobs else 0
    finally:
        store.close()


def _only_job(db: Path) -> JobRow:
    """The one job the store at ``db`` holds (the tests below run one scan each)."""
    store = JobStore(db, durable=False)
    try:
        (job,) = store.list_jobs()
        return job
    finally:
        store.close()


def _signalled_mid_scan(argv: list[str], db: Path, sig: signal.Signals,
                        preexec: Callable[[], None] | None = None) -> tuple[int, str, str]:
    """Run ``gonio ARGV`` as a child, send it ``sig`` once its first reading (of any job) is
    stored, and return its exit status, stdout and stderr (killed if it outlives the test)."""
    proc = subprocess.Popen([*GONIO, *argv], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env=child_env(), cwd=PROJECT_ROOT, preexec_fn=preexec)
    try:
        wait_for(lambda: _readings(db) > 0 or proc.poll() is not None,
                 what="the scan's first reading")
        assert proc.poll() is None, proc.communicate()
        proc.send_signal(sig)
        out, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
    return proc.returncode, out, err


def _slow_scan(rig: Path, data: Path, *more: str) -> list[str]:
    """``gonio scan`` argv of a scan slow enough to be signalled mid-way on a busy machine
    (six angles of 0.5 s exposures at real time) on the simulated rig ``rig``, its store in
    ``data``; ``more`` are added (``-o``, ``--accept-uncalibrated``)."""
    return ["scan", "--no-export-fits", *more, "--rig", str(rig), "--rotations", "6",
            "--exposure", "0.5", "--data-dir", str(data), "--no-progress"]


def test_ctrl_c_leaves_the_job_paused_and_the_same_command_resumes_it(tmp_path: Path) -> None:
    rig = tmp_path / "rig.toml"
    data = tmp_path / "data"
    db = data / "gonio.sqlite"
    # Real time and a long exposure: the scan lasts long enough to be interrupted mid-way.
    # Five angles (7 s or more of exposures) remain after the first is stored, so a test
    # process slowed by a busy machine still signals while the scan measures (with 4 angles
    # of 0.3 s, one run on a loaded machine saw the scan complete, exit 0, not 130).
    with start_sim_rig(SimRigOptions(time_scale=1.0, settle_s=0.0, config_path=rig)):
        argv = _slow_scan(rig, data, "-o", str(tmp_path / "felt.h5"))
        # SIGINT as a terminal's foreground job has it: a suite started in the background by a
        # non-interactive shell ignores SIGINT, and a child inherits that, so without the
        # reset the Ctrl-C below would be ignored and the scan would measure to its end.
        # SIGINT: what Ctrl-C in the terminal sends.
        code, out, err = _signalled_mid_scan(argv, db, signal.SIGINT, _default_sigint)
        assert code == 130, out + err
        job = _only_job(db)
        assert job.state is JobState.PAUSED, job
        assert job.done_angles < job.total_angles
        # The message says what happened and both ways on, with the real job and store.
        assert f"job {job.id} interrupted: paused" in err, err
        assert "Run the same command again to resume it" in err, err
        assert f"gonio jobs abort {job.id} --db {db}" in err, err
        listed = gonio(["jobs", "list", "--db", str(db)])
        assert "paused" in listed.stdout and "running" not in listed.stdout, listed.stdout
        # The same command again: resumed from its checkpoint, not started anew.
        again = gonio(argv, timeout=600)
        assert again.returncode == 0, again.stdout + again.stderr
        assert f"resuming job {job.id} from its checkpoint" in again.stderr, again.stderr
    store = JobStore(db, durable=False)
    jobs = store.list_jobs()
    store.close()
    assert [j.state for j in jobs] == [JobState.COMPLETED]


def test_jobs_abort_ends_an_unfinished_job_and_refuses_a_finished_one(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    db = tmp_path / "gonio.sqlite"
    store = JobStore(db)
    job = store.create_job(kind="uniform", specimen="felt", plan={}, rig={})
    store.set_state(job.id, JobState.RUNNING)
    store.set_state(job.id, JobState.PAUSED, reason="interrupted")
    store.close()
    assert main(["jobs", "abort", str(job.id), "--db", str(db)]) == 0
    store = JobStore(db, durable=False)
    assert store.get_job(job.id).state is JobState.ABORTED
    store.close()
    assert main(["jobs", "abort", str(job.id), "--db", str(db)]) == 2
    assert "only an unfinished job can be aborted" in capsys.readouterr().err
    assert main(["jobs", "abort", "99", "--db", str(db)]) == 2


def test_ctrl_c_in_the_sim_calibration_aborts_it_and_says_so(tmp_path: Path) -> None:
    """Ctrl-C while ``gonio scan --sim`` calibrates the simulated rig (before the scan) left
    the calibration job ``running`` for ever and printed only "interrupted": the next daemon
    on that data directory took it up with whatever was on the stage. It is aborted, and the
    message says so and what the same command does."""
    data = tmp_path / "data"
    db = data / "gonio.sqlite"
    # Real time and a long exposure: the calibration (4 angles x 12 pairs) lasts long enough.
    argv = ["scan", "--no-export-fits", "--sim", "--time-scale", "1", "--exposure", "0.3",
            "--data-dir", str(data), "--no-progress", "-o", str(tmp_path / "felt.h5")]
    # The first reading stored is the calibration's.
    code, out, err = _signalled_mid_scan(argv, db, signal.SIGINT, _default_sigint)
    assert code == 130, out + err
    job = _only_job(db)
    assert job.kind == "calibration" and job.state is JobState.ABORTED, job
    assert f"calibration job {job.id} interrupted and aborted" in err, err
    assert "The same command again calibrates the simulated rig anew" in err, err
    listed = gonio(["jobs", "list", "--db", str(db)])
    assert " aborted " in listed.stdout, listed.stdout
    assert "nothing goes on with job" not in listed.stdout + listed.stderr, listed


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP], ids=["SIGTERM", "SIGHUP"])
def test_sigterm_or_sighup_stops_the_scan_as_ctrl_c_does(
    tmp_path: Path, sig: signal.Signals
) -> None:
    """``kill``, ``timeout`` or a closed terminal killed gonio scan where it stood: the job
    stayed 'running' (listed as interrupted), nothing was said and the lamps were left as they
    were. Now the job is paused at its checkpoint and the message says how to go on."""
    rig = tmp_path / "rig.toml"
    data = tmp_path / "data"
    db = data / "gonio.sqlite"
    with start_sim_rig(SimRigOptions(time_scale=1.0, settle_s=0.0, config_path=rig)):
        argv = _slow_scan(rig, data, "--accept-uncalibrated", "-o", str(tmp_path / "felt.h5"))
        # The signal as a terminal's job has it: a suite run under nohup passes SIGHUP
        # ignored to its children, and gonio scan keeps an ignored signal ignored
        # (test_a_scan_under_nohup_survives_a_hangup), so the scan measured to its end, exit 0.
        code, out, err = _signalled_mid_scan(argv, db, sig, lambda: _default(sig))
    # What a shell reports for a process the signal ended (128 + its number), not Ctrl-C's.
    assert code == 128 + sig.value, out + err
    job = _only_job(db)
    assert job.state is JobState.PAUSED, job
    assert job.reason == f"interrupted ({sig.name} to gonio scan)", job
    assert f"{sig.name} received: stopping the scan as Ctrl-C does" in err, err
    assert f"job {job.id} interrupted: paused" in err, err
    assert "Run the same command again to resume it" in err, err


def test_a_scan_that_does_not_resume_the_paused_one_names_it(tmp_path: Path) -> None:
    """After Ctrl-C (here SIGTERM) a second command with another -o (which names the
    specimen) is another plan: it started a new job and said nothing of the paused one, which
    stayed paused in the store unmentioned."""
    rig = tmp_path / "rig.toml"
    data = tmp_path / "data"
    db = data / "gonio.sqlite"
    with start_sim_rig(SimRigOptions(time_scale=1.0, settle_s=0.0, config_path=rig)):
        argv = _slow_scan(rig, data, "--accept-uncalibrated")
        code, out, err = _signalled_mid_scan([*argv, "-o", str(tmp_path / "felt.h5")], db,
                                             signal.SIGTERM)
        assert code == 128 + signal.SIGTERM, out + err
        paused = _only_job(db)
        assert paused.state is JobState.PAUSED
        other = gonio([*argv, "--rotations", "2", "--exposure", "0.01",
                       "-o", str(tmp_path / "linen.h5")])
    assert other.returncode == 0, other.stdout + other.stderr
    assert (f"note: job {paused.id} ('felt', paused, {paused.done_angles} of 6 angles) is "
            "another unfinished job in this job store") in other.stderr, other.stderr
    assert f"'gonio jobs abort {paused.id} --db {db}' ends it" in other.stderr, other.stderr


def _sigterm_to_self(finished: list[bool]) -> tuple[list[str], bool]:
    """Install gonio scan's stop handlers with ``finished`` as the scan's completion flag,
    send this process SIGTERM, and return the stop record and whether the scan's task was
    cancelled (the process's own SIGTERM handler is given back afterwards)."""
    import asyncio
    import os

    from gonio.cli.scan_commands import _stop_on_terminate

    stopped: list[str] = []
    before = signal.getsignal(signal.SIGTERM)

    async def scan() -> bool:
        _stop_on_terminate(stopped, finished)
        # The loop's handler, or the signal below would end the test run itself.
        assert signal.getsignal(signal.SIGTERM) not in (before, signal.SIG_DFL), before
        os.kill(os.getpid(), signal.SIGTERM)
        try:
            for _ in range(500):
                if stopped:
                    break
                await asyncio.sleep(0.01)
            await asyncio.sleep(0.1)  # where the rest of the scan (the copy) would run
        except asyncio.CancelledError:
            return True
        return False

    try:
        cancelled = asyncio.run(scan())
    finally:
        signal.signal(signal.SIGTERM, before)
    return stopped, cancelled


def test_a_signal_after_the_job_completed_lets_the_command_write_its_result(
    capsys: pytest.CaptureFixture[str]
) -> None:
    """A SIGTERM that landed after the job had completed (while the service stopped) was
    reported "interrupted" and skipped the copy to -o: there was no scan left to stop. It is
    noted and the command ends as it would have; before completion it still stops the scan."""
    stopped, cancelled = _sigterm_to_self([True])
    assert stopped == ["SIGTERM"] and not cancelled
    err = capsys.readouterr().err
    assert "SIGTERM received: the scan has already completed; writing its result" in err, err
    stopped, cancelled = _sigterm_to_self([])
    assert stopped == ["SIGTERM"] and cancelled
    assert "stopping the scan as Ctrl-C does" in capsys.readouterr().err


def test_a_sigterm_while_the_completed_scan_shuts_down_still_writes_the_result(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """The whole command: a SIGTERM that lands while the service stops after the job has
    completed (here sent from inside that stop) is noted, the result is still copied to -o and
    the command ends 0; it was "interrupted", exit 130, and no copy."""
    import os

    from gonio.service import GonioService

    real_stop = GonioService.stop
    sent: list[bool] = []

    async def stop_with_a_signal(self: GonioService) -> None:
        if not sent:
            handler = signal.getsignal(signal.SIGTERM)
            # gonio scan's loop handler, or the signal would end the test run itself.
            assert handler not in (signal.SIG_DFL, signal.SIG_IGN), handler
            sent.append(True)
            os.kill(os.getpid(), signal.SIGTERM)
        await real_stop(self)

    monkeypatch.setattr(GonioService, "stop", stop_with_a_signal)
    before = signal.getsignal(signal.SIGTERM)
    rig, data, out = tmp_path / "rig.toml", tmp_path / "data", tmp_path / "felt.h5"
    try:
        with start_sim_rig(SimRigOptions(time_scale=10.0, settle_s=0.0, config_path=rig)):
            code = main(["scan", "--no-export-fits", "--accept-uncalibrated", "--rig", str(rig),
                         "--rotations", "2", "--data-dir", str(data), "--no-progress",
                         "-o", str(out)])
    finally:
        signal.signal(signal.SIGTERM, before)
    err = capsys.readouterr().err
    assert sent and code == 0, err
    assert "SIGTERM received: the scan has already completed; writing its result" in err, err
    assert out.read_bytes()[:8] == b"\x89HDF\r\n\x1a\n"  # the result, copied
    assert _only_job(data / "gonio.sqlite").state is JobState.COMPLETED


def _ignore_sighup() -> None:
    signal.signal(signal.SIGHUP, signal.SIG_IGN)  # what nohup does before it runs a command


def test_a_scan_under_nohup_survives_a_hangup(tmp_path: Path) -> None:
    """``nohup gonio scan ...`` outlived the SSH session that started it; the handler that
    makes SIGHUP stop a scan replaced nohup's SIG_IGN, so logging out stopped the scan. A
    signal ignored when the scan starts stays ignored: the scan measures to its end."""
    rig = tmp_path / "rig.toml"
    data = tmp_path / "data"
    db = data / "gonio.sqlite"
    out_file = tmp_path / "felt.h5"
    with start_sim_rig(SimRigOptions(time_scale=1.0, settle_s=0.0, config_path=rig)):
        argv = ["scan", "--no-export-fits", "--accept-uncalibrated",
                "--rig", str(rig), "--rotations", "4", "--exposure", "0.3",
                "--data-dir", str(data), "--no-progress", "-o", str(out_file)]
        code, out, err = _signalled_mid_scan(argv, db, signal.SIGHUP, _ignore_sighup)
    assert code == 0, out + err
    assert "SIGHUP received" not in err, err
    job = _only_job(db)
    assert job.state is JobState.COMPLETED and job.done_angles == 4, job
    assert out_file.is_file()


def test_a_sim_scan_resumes_only_on_the_material_it_was_measuring(tmp_path: Path) -> None:
    """``gonio scan --sim --material pile-000`` after an interrupted scan of the default
    material resumed that job on the new specimen: one result of two materials, naming only
    the second as its truth. It is refused now, nothing measured, the job kept as it was."""
    data = tmp_path / "data"
    db = data / "gonio.sqlite"
    argv = ["scan", "--sim", "--no-export-fits", "--rotations", "8", "--exposure", "0.2",
            "--data-dir", str(data), "--no-progress", "-o", str(tmp_path / "a.h5")]

    def scan_readings() -> int:  # the scan's, not the calibration's that runs first
        if not db.is_file():
            return 0
        store = JobStore(db, durable=False)
        try:
            return sum(len(store.readings(j.id)) for j in store.list_jobs()
                       if j.kind != "calibration")
        finally:
            store.close()

    proc = subprocess.Popen([*GONIO, *argv], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env=child_env(), cwd=PROJECT_ROOT,
                            preexec_fn=_default_sigint)
    try:
        wait_for(lambda: scan_readings() > 0 or proc.poll() is not None,
                 what="the scan's first reading")
        assert proc.poll() is None, proc.communicate()
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 130, out + err
    store = JobStore(db, durable=False)
    (job,) = [j for j in store.list_jobs() if j.kind != "calibration"]
    store.close()
    assert job.state is JobState.PAUSED, job
    kept = scan_readings()

    other = gonio([*argv, "--material", "pile-000"], timeout=300)
    assert other.returncode == 2, other.stdout + other.stderr
    assert (f"job {job.id} was measuring the default material when it was interrupted"
            in other.stderr), other.stderr
    assert "Run the same command without --material to finish it" in other.stderr
    assert f"gonio jobs abort {job.id} --db {db}" in other.stderr
    store = JobStore(db, durable=False)
    assert store.get_job(job.id).state is JobState.PAUSED
    store.close()
    assert scan_readings() == kept
