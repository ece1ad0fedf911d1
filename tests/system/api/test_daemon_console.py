"""The daemon's console says what happened to jobs, not every request (issue 27, item 9).

A real ``gonio serve --sim`` child process: its start-up calibration job, a scan aborted by
request, and a page's worth of polling in between.
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import httpx
import pytest

from tests.system.daemon_proc import wait_for

pytestmark = pytest.mark.system

KEY = "k" * 32


def test_console_logs_job_lifecycle_and_calibration_but_not_polls(tmp_path: Path) -> None:
    env = {**os.environ, "GONIO_API_KEYS": f"tester:{KEY}", "PYTHONUNBUFFERED": "1"}
    proc = subprocess.Popen(
        [sys.executable, "-c", "from gonio.cli import main; raise SystemExit(main())",
         "serve", "--sim", "--no-export-fits", "--time-scale", "10", "--port", "0", "--data-dir",
         str(tmp_path / "data")],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env)
    lines: list[str] = []
    url: list[str] = []

    def pump() -> None:
        assert proc.stdout is not None
        for line in proc.stdout:
            lines.append(line.rstrip("\n"))
            m = re.match(r"gonio serving on (\S+)", line)
            if m:
                url.append(m.group(1))

    threading.Thread(target=pump, daemon=True).start()
    try:
        wait_for(lambda: url or proc.poll() is not None, what="the daemon to listen")
        assert url, "\n".join(lines)
        with httpx.Client(base_url=url[0], headers={"X-API-Key": KEY}, timeout=30) as c:
            # The start-up calibration (job 1) runs while a page polls.
            deadline = time.monotonic() + 300
            while c.get("/api/v1/jobs/1").json()["state"] != "completed":
                assert time.monotonic() < deadline, "\n".join(lines)
                c.get("/api/v1/rig")
                time.sleep(0.2)
            job = c.post("/api/v1/jobs", json={"plan": {
                "kind": "uniform", "specimen": "felt", "rotations": 64}}).json()["id"]
            wait_for(lambda: c.get(f"/api/v1/jobs/{job}").json()["done_angles"] >= 1,
                     what="the scan's first angle")
            assert c.post(f"/api/v1/jobs/{job}/abort").status_code == 200
            wait_for(lambda: c.get(f"/api/v1/jobs/{job}").json()["state"] == "aborted",
                     what="the abort")
            wait_for(lambda: any(f"job {job} " in x and "aborted" in x for x in lines),
                     what="the abort's log line")
    finally:
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(timeout=60)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
    text = "\n".join(lines)
    # What happened, one line each.
    assert re.search(r"job 1 \(calibration, .*\) started: [1-9]\d* stage angles", text), text
    assert re.search(r"job 1 \(calibration, .*\) completed: calibration applied "
                     r"\(job 1: .*white reference.*, \d+ pairs\): later scans are in 1/sr",
                     text), text
    assert re.search(rf"job {job} \(uniform, 'felt'\) started", text), text
    assert re.search(rf"job {job} \(uniform, 'felt'\) aborted \(\d+ of 64 angles\): aborted "
                     "by request", text), text
    # Not every request: the polls are gone, the change is there.
    assert not re.search(r'"GET /api/v1/(jobs|rig)', text), text
    assert re.search(r'"POST /api/v1/jobs HTTP/1.1" 201', text), text


# RoutineRequestFilter itself: tests/unit/test_logfilters.py.
