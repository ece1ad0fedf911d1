"""Over HTTP: a half-turn plan on a daemon whose default basis lacks the twofold symmetry
(the ``odd_daemon`` fixture). The dry run warns a half-turn plan and
names the way out; a full-turn plan is not warned; a submitted half-turn job is queued (a
warning, not a refusal) and its events carry the warning.
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

import httpx
import pytest

from tests.system.api.conftest import Daemon

pytestmark = pytest.mark.system

FAST = {"exposure_s": 0.005, "averages": 1, "light_settle_s": 0.0}
FINAL = ("completed", "failed", "aborted", "halted")


def arc_warnings(warnings: list[str]) -> list[str]:
    """The dry run's warnings but the uncalibrated rig's (this daemon is not calibrated)."""
    return [w for w in warnings if not w.startswith("uncalibrated")]


def says_what_and_what_to_do(message: str) -> None:
    """The arc warning says what is wrong (the named material) and what to do."""
    assert "twofold symmetry" in message and "pile-lean" in message
    assert "other half" in message and "prior" in message
    assert "span_deg 360" in message and "--span 360" in message


def test_the_dry_run_warns_a_half_turn_plan_and_the_job_carries_it(odd_daemon: Daemon) -> None:
    with odd_daemon.client() as c:
        half = {"kind": "uniform", "rotations": 4, "span_deg": 180, "exposure": FAST}
        r = c.post("/api/v1/jobs/dry-run", json={"plan": half})
        assert r.status_code == 200, r.text
        (message,) = arc_warnings(r.json()["warnings"])
        says_what_and_what_to_do(message)
        full = {**half, "span_deg": 360}
        assert arc_warnings(c.post("/api/v1/jobs/dry-run",
                                   json={"plan": full}).json()["warnings"]) == []

        seq0 = c.get("/health").json()["seq"]
        r = c.post("/api/v1/jobs", json={"plan": half})
        assert r.status_code == 201, r.text  # warned, not refused
        job = r.json()["id"]
        # Let the job end before the daemon stops (its outcome is not under test).
        deadline = time.monotonic() + 120
        while c.get(f"/api/v1/jobs/{job}").json()["state"] not in FINAL:
            assert time.monotonic() < deadline
            time.sleep(0.2)
        mine = [e for e in _events_since(c, seq0) if e["job_id"] == job]
        warned = [e for e in mine if e["type"] == "arc_warning"]
        assert len(warned) == 1  # at queueing, not again when the worker had the basis
        assert warned[0]["data"]["materials"] == ["pile-lean"]
        says_what_and_what_to_do(warned[0]["data"]["message"])
        # Before anything was measured.
        assert [e["type"] for e in mine].index("arc_warning") < [
            e["type"] for e in mine].index("progress")


def _events_since(c: httpx.Client, seq: int) -> list[dict[str, Any]]:
    """The stored events after ``seq``, from the event stream's replay, up to the last one
    stored now (the stream is closed by this client, not left to the server's shutdown)."""
    last = c.get("/health").json()["seq"]
    out: list[dict[str, Any]] = []
    with c.stream("GET", "/api/v1/events", params={"since": seq}) as resp:
        resp.raise_for_status()
        for line in resp.iter_lines():
            if line.startswith("data:"):
                out.append(json.loads(line[5:].strip()))
                if out[-1]["seq"] >= last:
                    break
    return out


def test_gonio_scan_through_the_daemon_says_it_before_queueing(
        odd_daemon: Daemon, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from gonio.cli import main

    out = tmp_path / "a.h5"
    argv = ["scan", "--daemon", odd_daemon.url, "--api-key", odd_daemon.key, "--rotations", "3",
            "--exposure", "0.005", "--light-settle", "0", "--no-progress", "-o", str(out)]
    assert main(argv) == 0 and out.is_file()  # warned, not refused
    err = capsys.readouterr().err
    # The arc warning, told by its own words (the 3-angle scan with this small basis is also
    # warned of as uncalibrated and, at its end, as missing its readings: basis misfit).
    (line,) = [ln for ln in err.splitlines()
               if ln.startswith("warning:") and "over half a turn" in ln]
    says_what_and_what_to_do(line)
    assert err.index(line) < err.index("queued on")
    assert main([*argv, "--span", "360", "--overwrite"]) == 0  # the same -o again
    assert [ln for ln in capsys.readouterr().err.splitlines()
            if ln.startswith("warning:") and "over half a turn" in ln] == []
