"""``gonio serve --sim`` killed mid-scan and restarted on its data directory.

The resumed job must measure the specimen it started with (not the white reference a
start-up calibration would put on the stage), and no second calibration is queued: the
calibration of the first run is still in effect. The resumed readings are compared with a
clean run's of the same plan on a fresh data directory (same simulated rig and noise model).
Real processes, real HTTP, ``kill -9``.
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pytest

pytestmark = [pytest.mark.system, pytest.mark.timeout(420)]

MEASURED = ("reconstructing", "completed")
PLAN = {"kind": "uniform", "specimen": "felt", "rotations": 8}
SLOW = "2"
"""Time scale of the run that is killed: each angle takes about half a second, so the kill
lands mid-scan."""
FAST = "10"
"""Time scale of the resumed and the clean run (it changes only how long motion and exposures
take in wall time, not the readings)."""


class Daemon:
    """A ``gonio serve --sim`` child process; its stdout collected by a thread."""

    def __init__(self, data_dir: Path, time_scale: str, *extra: str) -> None:
        code = "from gonio.cli import main; raise SystemExit(main())"
        self.proc = subprocess.Popen(
            [sys.executable, "-c", code, "serve", "--sim", "--no-export-fits", "--port", "0",
             "--time-scale",
             time_scale, "--data-dir", str(data_dir), *extra],
            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=dict(os.environ),
        )
        self.lines: list[str] = []
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()
        m = self.wait_for(r"open (http://\S+/)#key=(\S+)")
        self.url, self.key = m.group(1), m.group(2)
        self.client = httpx.Client(base_url=self.url, headers={"X-API-Key": self.key},
                                   timeout=30)

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            self.lines.append(line.rstrip("\n"))

    def output(self) -> str:
        return "\n".join(self.lines)

    def wait_for(self, pattern: str, timeout: float = 120) -> re.Match[str]:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            for line in list(self.lines):
                m = re.search(pattern, line)
                if m:
                    return m
            if self.proc.poll() is not None and not self._reader.is_alive():
                break
            time.sleep(0.05)
        raise AssertionError(f"no line matching {pattern!r}; output:\n{self.output()}")

    def job(self, job_id: int) -> dict[str, Any]:
        r = self.client.get(f"/api/v1/jobs/{job_id}")
        r.raise_for_status()
        return dict(r.json())

    def wait_job(self, job_id: int, until: Any, timeout: float = 180) -> dict[str, Any]:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            job = self.job(job_id)
            if until(job):
                return job
            if job["state"] in ("failed", "aborted", "halted"):
                raise AssertionError(f"job {job_id} {job['state']}: {job.get('reason')}")
            time.sleep(0.05)
        raise AssertionError(f"job {job_id} did not get there: {self.job(job_id)}")

    def readings(self, job_id: int) -> dict[tuple[int, str, str], np.ndarray]:
        r = self.client.get(f"/api/v1/jobs/{job_id}/readings")
        r.raise_for_status()
        return {(x["angle_index"], x["light"], x["sensor"]): np.asarray(x["values"])
                for x in r.json()}

    def stop(self, sig: int = signal.SIGTERM) -> None:
        self.client.close()
        if self.proc.poll() is None:
            self.proc.send_signal(sig)
            try:
                self.proc.wait(timeout=30)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(timeout=10)


@contextmanager
def daemon(data_dir: Path, time_scale: str = FAST, *extra: str) -> Iterator[Daemon]:
    d = Daemon(data_dir, time_scale, *extra)
    try:
        yield d
    finally:
        d.stop()


def _calibrated_and_submitted(d: Daemon) -> int:
    d.wait_for(r"calibrating the simulated rig: job 1")
    d.wait_job(1, lambda j: j["state"] == "completed")
    # The lab's zero is not the servo's: the stage homed a quarter turn from where it
    # starts. A restart forgot it (the simulated servo's Homing Offset was not kept, where a
    # real servo's EEPROM keeps it), and the resumed angles read the specimen 90 degrees off.
    for command in ({"action": "move", "angle_deg": 90.0}, {"action": "home"}):
        r = d.client.post("/api/v1/rig/stage", json=command)
        assert r.status_code == 200, r.text
    r = d.client.post("/api/v1/jobs", json={"plan": PLAN})
    assert r.status_code == 201, r.text
    return int(r.json()["id"])


def test_killed_sim_daemon_resumes_its_specimen_scan_without_recalibrating(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    data = tmp_path / "data"
    # The daemons' temporary folders (the simulated rig's config), where the test sees them.
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    monkeypatch.setenv("TMPDIR", str(tmp))
    # 1. First run: calibrate, start a scan, kill -9 in the middle of it.
    with daemon(data, SLOW) as first:
        assert f"data directory {data} (kept across restarts)" in first.output()
        job_id = _calibrated_and_submitted(first)
        at_kill = first.wait_job(job_id, lambda j: j["done_angles"] >= 2
                                 or j["state"] in MEASURED)
        first.proc.kill()  # SIGKILL: no clean-up of any kind
        first.proc.wait(timeout=30)
    # Each angle takes about half a second here, so the kill lands mid-scan.
    assert at_kill["state"] == "running" and at_kill["done_angles"] < 8, at_kill
    # Its temporary folder stayed behind, naming the process that was killed.
    (left,) = tmp.glob("gonio-serve-*")
    assert (left / "gonio-serve.pid").read_text() == str(first.proc.pid)

    # 2. Restart on the same data directory: the scan resumes on its specimen, with the
    #    zero it started with, and no new calibration job is queued.
    with daemon(data) as second:
        second.wait_for(r"calibration: in effect")
        # The next start removed it (the killed session's); its own folder is there instead.
        assert not left.exists()
        assert [p.name for p in tmp.glob("gonio-serve-*/gonio-serve.pid")] == ["gonio-serve.pid"]
        # The same API key as before the kill: a page left open (the key in its tab) keeps
        # working; it was a new key each start. Kept owner-only in the data directory.
        assert second.key == first.key
        assert "API key: the one of the last start on this data directory" in second.output()
        assert (data / "sim-session.key").stat().st_mode & 0o777 == 0o600
        resumed = second.wait_job(job_id, lambda j: j["state"] in MEASURED)
        assert resumed["done_angles"] == 8
        jobs = second.client.get("/api/v1/jobs").json()
        assert [j["id"] for j in jobs if j["kind"] == "calibration"] == [1]
        assert "calibrating the simulated rig" not in second.output()
        got = second.readings(job_id)

    # 3. A clean run of the same plan on a fresh data directory.
    with daemon(tmp_path / "clean") as clean:
        clean_id = _calibrated_and_submitted(clean)
        clean.wait_job(clean_id, lambda j: j["state"] in MEASURED)
        want = clean.readings(clean_id)
        assert clean.key != first.key  # another data directory: a key of its own

    assert sorted(got) == sorted(want) and len(got) == 8 * 12
    a = np.stack([got[k] for k in sorted(got)])
    b = np.stack([want[k] for k in sorted(want)])
    # Same specimen, same rig: equal within the simulated sensor noise (shot noise of a few
    # hundred counts on readings of 10^3..10^5; the white reference would read 1.5-4x higher).
    np.testing.assert_allclose(a, b, rtol=0.05, atol=60.0)


def test_the_first_start_says_how_a_shell_gives_the_session_key(tmp_path: Path) -> None:
    """The session's key was only in the page's address: a lab going on from a shell (gonio
    jobs --daemon, gonio scan --daemon) was refused. The start says how to give it, and the
    line, followed as printed, is let in where the same command without it is refused."""
    with daemon(tmp_path / "data", FAST) as d:
        m = d.wait_for(r"from a shell: export GONIO_API_KEY=(\S+), then e\.g\. (gonio jobs "
                       r"--daemon (\S+) list)")
        assert m.group(1) == d.key and m.group(3) == d.url.rstrip("/")
        d.wait_job(1, lambda j: j["state"] == "completed")
        code = "from gonio.cli import main; raise SystemExit(main())"
        # A write: cancelling the completed calibration job. With the key the daemon looks
        # at the job (and refuses: it is not queued); without it, at the key.
        cmd = [sys.executable, "-c", code, "jobs", "--daemon", m.group(3), "cancel", "1"]
        env = {k: v for k, v in os.environ.items() if k != "GONIO_API_KEY"}
        keyless = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=60)
        keyed = subprocess.run(cmd, env={**env, "GONIO_API_KEY": m.group(1)},
                               capture_output=True, text=True, timeout=60)
    assert keyless.returncode != 0 and "give a key" in keyless.stderr, keyless.stderr
    assert keyed.returncode != 0 and "give a key" not in keyed.stderr, keyed.stderr
    assert "cannot cancel job 1: it is completed" in keyed.stderr, keyed.stderr
