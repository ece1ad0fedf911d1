"""``gonio jobs list`` on a store nobody runs says that its 'running' jobs are not measuring:
after a daemon was stopped mid-job (SIGTERM or kill -9) the list read 'running 3/8' with no
process behind it, and nothing said it waits for the next start (or how to end it)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from gonio.cli import main
from gonio.jobstates import JobState
from gonio.store import JobStore

pytestmark = pytest.mark.system

HOLD = """
import sys, time
from gonio.locks import claim_store
claim_store(sys.argv[1])
print("held", flush=True)
time.sleep(60)
"""


def _store_with_a_running_job(db: Path) -> int:
    store = JobStore(db)
    try:
        job = store.create_job(kind="uniform", specimen="felt", plan={"kind": "uniform"},
                               rig={})
        store.set_state(job.id, JobState.RUNNING)
        return job.id
    finally:
        store.close()


def test_a_running_job_with_no_process_behind_it_is_said_to_be_interrupted(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    db = tmp_path / "gonio.sqlite"
    job = _store_with_a_running_job(db)
    assert main(["jobs", "list", "--db", str(db)]) == 0
    out = capsys.readouterr().out
    assert "running" in out
    assert "no daemon or gonio scan runs jobs from this store now, so nothing goes on with " \
        f"job(s) {job} above" in out
    assert f"'gonio jobs abort ID --db {db}'" in out
    # While a process holds the store (a daemon), 'running' is live: no note.
    holder = subprocess.Popen([sys.executable, "-c", HOLD, str(db)], stdout=subprocess.PIPE,
                              text=True)
    try:
        assert holder.stdout is not None and holder.stdout.readline().strip() == "held"
        assert main(["jobs", "list", "--db", str(db)]) == 0
        assert "no daemon" not in capsys.readouterr().out
    finally:
        holder.kill()
        holder.wait()
    assert main(["jobs", "list", "--db", str(db)]) == 0
    assert "no daemon or gonio scan runs jobs" in capsys.readouterr().out


def test_the_data_directory_serves_for_its_store(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # gonio serve and gonio scan print the data directory; --db DATA_DIR said 'job store
    # DATA_DIR does not exist' though the store is in it.
    _store_with_a_running_job(tmp_path / "gonio.sqlite")
    assert main(["jobs", "list", "--db", str(tmp_path)]) == 0
    assert "felt" in capsys.readouterr().out
    empty = tmp_path / "empty"
    empty.mkdir()
    assert main(["jobs", "list", "--db", str(empty)]) == 2
    assert "is a folder without a job store (gonio.sqlite)" in capsys.readouterr().err


def test_data_dir_alone_names_the_store(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # 'gonio jobs list --data-dir DIR' (the folder gonio scan prints, as gonio scan takes it)
    # was refused: "which job store? --db is required".
    _store_with_a_running_job(tmp_path / "gonio.sqlite")
    assert main(["jobs", "list", "--data-dir", str(tmp_path)]) == 0
    assert "felt" in capsys.readouterr().out
    assert main(["jobs", "show", "1", "--data-dir", str(tmp_path)]) == 0
    assert "job 1:" in capsys.readouterr().out
    empty = tmp_path / "empty"
    empty.mkdir()
    assert main(["jobs", "list", "--data-dir", str(empty)]) == 2
    err = capsys.readouterr().err
    assert f"--data-dir {empty} holds no job store (gonio.sqlite)" in err, err


def test_list_with_a_job_id_says_show_takes_one_and_a_non_store_is_named(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    db = tmp_path / "gonio.sqlite"
    _store_with_a_running_job(db)
    # `gonio jobs list 1` listed every job, the 1 silently dropped.
    assert main(["jobs", "list", "1", "--db", str(db)]) == 2
    err = capsys.readouterr().err
    assert f"list takes no job id; 'gonio jobs show 1 --db {db}' shows job 1" in err, err
    # A rebuild of a job still running is refused, and does not first say it is rebuilding.
    assert main(["jobs", "rebuild", "1", "--db", str(db)]) == 2
    err = capsys.readouterr().err
    assert "job 1 is running" in err and "rebuilding" not in err, err
    # A rig config given as the store read "point --db at a new file", which lists nothing.
    rig = tmp_path / "rig.toml"
    rig.write_text('[rig]\nname = "sim"\n' * 200)
    assert main(["jobs", "list", "--db", str(rig)]) == 2
    err = capsys.readouterr().err
    assert f"{rig} is not a usable gonio job store" in err, err
    assert "DATA_DIR/gonio.sqlite, the one 'gonio scan' and the daemon print" in err, err


HOLD_AS_DAEMON = """
import sys, time
from gonio.locks import advertise_url, claim_store
advertise_url("http://127.0.0.1:8321/")
claim_store(sys.argv[1])
print("held", flush=True)
time.sleep(60)
"""


def test_queued_jobs_of_a_store_a_daemon_runs_point_to_its_start_estimates(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The store alone cannot say when a queued job starts (the time left of the job under
    way is the daemon's): the list names the daemon's command that can, at the address the
    daemon's lock records; a store nobody runs gets no such note."""
    db = tmp_path / "gonio.sqlite"
    store = JobStore(db)
    try:
        store.create_job(kind="uniform", specimen="felt", plan={"kind": "uniform"}, rig={})
    finally:
        store.close()
    assert main(["jobs", "list", "--db", str(db)]) == 0
    assert "note:" not in capsys.readouterr().out
    holder = subprocess.Popen([sys.executable, "-c", HOLD_AS_DAEMON, str(db)],
                              stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout is not None and holder.stdout.readline().strip() == "held"
        assert main(["jobs", "list", "--db", str(db)]) == 0
        out = capsys.readouterr().out
    finally:
        holder.kill()
        holder.wait()
    assert ("note: the daemon at http://127.0.0.1:8321 runs this store; 'gonio jobs --daemon "
            "http://127.0.0.1:8321 list' adds when each queued job may start") in out, out
