"""A full data directory disk: the daemon keeps running, says so, and loses nothing.

The disk is a real one, a small tmpfs mounted for the test, so every write goes through the
real code path: SQLite's own "database or disk is full", h5py/HDF5 and plain file writes all
meet ENOSPC from the kernel. (RLIMIT_FSIZE, the unprivileged alternative, gives EFBIG and
SIGXFSZ instead, which SQLite reports as an I/O error rather than a full disk: a different
path.) Mounting needs root (CAP_SYS_ADMIN); elsewhere the test is skipped with that reason.
"""

from __future__ import annotations

import errno
import shutil
import signal
import subprocess
import sys
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import httpx
import pytest

from gonio.basis_supply import BasisSupply
from gonio.diskspace import FREE_MARGIN_BYTES
from gonio.results import read_result
from tests.system.daemon_proc import DaemonProcess, gonio, start_daemon, wait_for

pytestmark = [pytest.mark.system, pytest.mark.timeout(400)]

TMPFS_MB = 96  # above the worker's free-space margin once the filler is gone
assert TMPFS_MB * 2**20 > 2 * FREE_MARGIN_BYTES


@pytest.fixture
def small_disk(tmp_path: Path) -> Iterator[Path]:
    """A tmpfs of TMPFS_MB MiB mounted for this test (skipped where mounting is refused)."""
    if not sys.platform.startswith("linux") or shutil.which("mount") is None:
        pytest.skip("needs Linux mount(8) for a small tmpfs")
    mnt = tmp_path / "disk"
    mnt.mkdir()
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={TMPFS_MB}m,mode=0700", "tmpfs",
                        str(mnt)], capture_output=True, text=True, check=False)
    if r.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here (needs root): {r.stderr.strip()}")
    try:
        yield mnt
    finally:
        subprocess.run(["umount", "-l", str(mnt)], capture_output=True, check=False)


def fill(disk: Path) -> Path:
    """Write zeros into ``disk`` until the kernel refuses (ENOSPC); returns the filler."""
    filler = disk / "filler"
    with open(filler, "wb", buffering=0) as f:
        for chunk in (2**20, 4096, 1):
            block = bytes(chunk)
            try:
                while True:
                    f.write(block)
            except OSError as exc:
                assert exc.errno == errno.ENOSPC
    return filler


def _serve(data: Path) -> DaemonProcess:
    return start_daemon(["--sim", "--data-dir", str(data), "--port", "0",
                         "--time-scale", "10"])


def _job(d: DaemonProcess, job_id: int) -> dict[str, Any]:
    with d.client() as c:
        r = c.get(f"/api/v1/jobs/{job_id}")
        assert r.status_code == 200, r.text
        return r.json()  # type: ignore[no-any-return]


def _health(d: DaemonProcess) -> dict[str, Any]:
    with d.client() as c:
        r = c.get("/health")
        assert r.status_code == 200, r.text
        return r.json()  # type: ignore[no-any-return]


def test_a_disk_filling_during_a_job_fails_the_job_not_the_daemon(small_disk: Path) -> None:
    data = small_disk / "data"
    d = _serve(data)
    try:
        # serve --sim calibrates at start (job 1); then a long calibration job (no basis to
        # build) whose readings and calibration the disk will have no room for.
        wait_for(lambda: _job(d, 1)["state"] == "completed", 180, "the start-up calibration")
        with d.client() as c:
            plan = {"kind": "calibration", "reference_albedo": 0.99, "rotations": 60}
            r = c.post("/api/v1/jobs", json={"plan": plan})
            assert r.status_code == 201, r.text
            job = r.json()["id"]
        wait_for(lambda: _job(d, job)["done_angles"] >= 1, 120, "the first angle")
        filler = fill(small_disk)

        # Whichever write meets the full disk first (a checkpoint, the job's state, the
        # calibration file), the job ends failed with "disk full", now or once the store has
        # room; the daemon keeps serving and says why nothing runs.
        wait_for(lambda: f"job {job}" in (_health(d).get("disk_full") or ""), 180,
                 "the job's disk-full failure on /health")
        health = _health(d)
        assert health["status"] == "disk_full" and health["disk_full"].startswith("disk full")
        assert d.proc.poll() is None, d.text()
        _refused(d)
        assert d.proc.poll() is None, d.text()

        # Room again: what the store could not record is recorded, and jobs may run.
        filler.unlink()
        wait_for(lambda: _health(d)["status"] == "ok", 60, "/health ok once there is room")
        failed = _job(d, job)
        assert failed["state"] == "failed" and failed["reason"].startswith("disk full"), failed
        assert failed["done_angles"] >= 1  # its readings are kept
        # Failed part way through its measurement: not a whole scan, and rebuild says so.
        r = gonio(["jobs", "rebuild", str(job), "--db", str(data / "gonio.sqlite")])
        assert r.returncode == 2, r.stdout + r.stderr
        assert f"job {job} failed while it was measuring" in r.stderr, r.stderr
        assert "measure it again" in r.stderr and "Traceback" not in r.stderr, r.stderr
        assert _job(d, job)["state"] == "failed"

        filler = fill(small_disk)
    finally:
        status = d.stop(signal.SIGTERM)
    assert status == 0, d.text()  # no SIGSEGV (-11), no dead worker (1)
    assert "Traceback" not in d.text()

    # A restart while the disk is full starts, says so, and refuses new jobs with a reason.
    d = _serve(data)
    try:
        assert _health(d)["status"] == "disk_full"
        _refused(d)
        filler.unlink()
        wait_for(lambda: _health(d)["status"] == "ok", 60, "/health ok once there is room")
        assert _job(d, job)["state"] == "failed"
        first = _job(d, 1)
        assert first["state"] == "completed"
        # The store's result paths are relative to the data directory.
        assert read_result(data / first["result_path"]).samples.values.size > 0
        assert not list((data / "results").glob("*.part"))
        assert (data / "calibration.json").is_file()
        assert not list(data.glob("calibration.json.*.part"))
    finally:
        assert d.stop() == 0, d.text()
    assert "Traceback" not in d.text()


def _refused(d: DaemonProcess) -> None:
    """A new job is refused with the API's JSON error body, 507, saying "disk full"."""
    with d.client() as c:
        refused = c.post("/api/v1/jobs", json={"plan": {"kind": "uniform", "specimen": "x",
                                                        "rotations": 4}})
        assert refused.status_code == 507, refused.text
        assert refused.headers["content-type"] == "application/json"
        assert refused.json()["detail"].startswith("disk full")
        assert c.get("/api/v1/jobs").status_code == 200  # reads still work


@contextmanager
def _released(event: threading.Event) -> Iterator[None]:
    """Set ``event`` on the way out, however the block ends (a held thread goes on)."""
    try:
        yield
    finally:
        event.set()


def test_a_disk_filling_while_the_result_file_is_written_fails_the_job_only(
    small_disk: Path, basis: Any, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The reconstruction's HDF5 file meets the full disk part way through (its first bytes
    fit, its table does not): the case that crashed the daemon with SIGSEGV when HDF5 wrote
    to the disk itself. Then an export of an earlier job meets it too. The daemon runs in
    this process, with a small basis."""
    import secrets

    from gonio import results
    from gonio.api.auth import ApiKeyring
    from gonio.daemon import DaemonConfig, build_app
    from gonio.sim.rig import SimRigOptions, start_sim_rig
    from tests.system.api.live_server import live_server

    data = small_disk / "data"
    key = secrets.token_hex(24)
    # The second job's result is written only once the disk is full: the real write_result,
    # held at its start while ``hold`` is set, so the filling cannot come too late.
    hold, reached, filled = threading.Event(), threading.Event(), threading.Event()
    write_result = results.write_result

    def held_write_result(*args: Any, **kwargs: Any) -> Path:
        if hold.is_set():
            reached.set()
            assert filled.wait(240), "the disk was not filled"
        return write_result(*args, **kwargs)

    monkeypatch.setattr(results, "write_result", held_write_result)
    with start_sim_rig(SimRigOptions(time_scale=10.0, settle_s=0.0)) as sim, \
            _released(filled):
        cfg = DaemonConfig().with_overrides(paths__data_dir=str(data))
        app = build_app(cfg, sim.config, ApiKeyring({"t": key}), basis=BasisSupply(lambda: basis))
        with live_server(app) as url, httpx.Client(base_url=url, headers={"X-API-Key": key},
                                                   timeout=120) as c:
            def submit() -> int:
                r = c.post("/api/v1/jobs", json={"plan": {"kind": "uniform", "specimen": "x",
                                                          "rotations": 4}})
                assert r.status_code == 201, r.text
                return int(r.json()["id"])

            def state(job: int) -> str:
                return str(c.get(f"/api/v1/jobs/{job}").json()["state"])

            done = submit()  # a result to export later, with its fits stored
            wait_for(lambda: state(done) == "completed", 240, "the first scan")
            # The second job and its rebuild without them: nothing here is about its fits.
            app.state.service.worker.fit_exports = False
            hold.set()
            job = submit()
            assert reached.wait(240), f"job {job} never wrote its result"
            hold.clear()
            assert state(job) == "reconstructing"
            # Leave 64 KiB: the file's header fits, the 72x18x18x36 table does not.
            filler = fill(small_disk)
            with open(filler, "r+b") as f:
                f.truncate(filler.stat().st_size - 64 * 1024)
            filled.set()
            wait_for(lambda: state(job) == "failed", 120, "the job's failure")
            detail = c.get(f"/api/v1/jobs/{job}").json()
            assert detail["reason"].startswith(f"disk full: the result file of job {job}")
            assert c.get("/health").json()["status"] == "disk_full"
            assert not list((data / "results").glob(f"job-{job}.h5*"))  # no torn file
            # An export (a few MB: the whole table) has no room either.
            export = c.get(f"/api/v1/jobs/{done}/export", params={"format": "table"})
            assert export.status_code == 507, export.text
            assert export.headers["content-type"] == "application/json"
            assert export.json()["detail"].startswith("disk full")
            assert not list((data / "exports").glob("*.part"))
            assert state(done) == "completed"
            filler.unlink()
            wait_for(lambda: c.get("/health").json()["status"] == "ok", 60, "room again")
            export = c.get(f"/api/v1/jobs/{done}/export", params={"format": "table"})
            assert export.status_code == 200 and len(export.content) > 0

            # Its readings are all stored: once there is room, gonio jobs rebuild (its own
            # store handle, beside the running daemon) writes the result and completes it.
            from gonio.finishing import rebuild_result
            from gonio.store import JobStore

            store = JobStore(data / "gonio.sqlite", durable=False)
            summary = rebuild_result(store, data, job, BasisSupply(lambda: basis))
            detail = c.get(f"/api/v1/jobs/{job}").json()
            assert detail["state"] == "completed", detail
            assert "completed by gonio jobs rebuild" in detail["reason"], detail
            # With the calibration it was being finished with (the same as the first scan's).
            assert detail["result"]["calibration"] == \
                c.get(f"/api/v1/jobs/{done}").json()["result"]["calibration"]
            assert detail["result"]["result_path"] == summary["result_path"]
            served = c.get(f"/api/v1/jobs/{job}/result")
            assert served.status_code == 200, served.text
            first, rebuilt = read_result(data / f"results/job-{done}.h5"), read_result(
                data / summary["result_path"])
            assert rebuilt.table is not None and first.table is not None
            assert rebuilt.provenance["rig_config"] == first.provenance["rig_config"]
