"""A foreground ``gonio scan`` whose job suspends says why on the terminal: the bar alone read
'job 1 suspended' (with pymodbus's 'Failed to connect ... Repeating....'), while the reason a
person needs (which device, which address, what to check) sat only in the job store."""

from __future__ import annotations

import re
import signal
import socket
import subprocess
from pathlib import Path

import pytest

from gonio.sim.rig import SimRigOptions, start_sim_rig
from tests.system.daemon_proc import GONIO, PROJECT_ROOT, child_env, wait_for

pytestmark = [pytest.mark.system, pytest.mark.timeout(300)]


def _closed_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def test_a_suspended_scan_prints_the_reason(tmp_path: Path) -> None:
    rig = tmp_path / "rig.toml"
    wrong = tmp_path / "wrong-port.toml"
    err = tmp_path / "stderr.txt"
    with start_sim_rig(SimRigOptions(config_path=rig)):
        text = rig.read_text()
        port = re.search(r"^port = (\d+)$", text, re.M)
        assert port is not None, text
        closed = _closed_port()
        # The first Modbus device (light L1) on a port nothing listens on: a typo'd port.
        wrong.write_text(text.replace(f"port = {port[1]}", f"port = {closed}", 1))
        with err.open("w") as f:
            proc = subprocess.Popen(
                [*GONIO, "scan", "--rig", str(wrong), "--rotations", "4", "--no-export-fits",
                 "--data-dir", str(tmp_path / "data"), "--no-progress",
                 "-o", str(tmp_path / "x.h5")],
                stdout=subprocess.DEVNULL, stderr=f, env=child_env(), cwd=PROJECT_ROOT)
            try:
                wait_for(lambda: "suspended:" in err.read_text() or proc.poll() is not None,
                         what="the scan to say why it is suspended")
                # What it said it does on Ctrl-C, it does: the job is left paused.
                proc.send_signal(signal.SIGINT)
                proc.wait(timeout=60)
            finally:
                proc.kill()
                proc.wait()
    out = err.read_text()
    assert f"job 1 suspended: L1: no Modbus TCP connection to 127.0.0.1:{closed}" in out, out
    # It said what happens next: the scan then waited in silence, like a hang.
    assert "the scan retries and goes on once it answers; Ctrl-C leaves the job paused, " \
           "and the same command resumes it" in out, out
    assert "job 1 interrupted: paused at its checkpoint" in out, out
    assert "check that the device is powered and the host/port in the rig config" in out, out
    # pymodbus' own lines add nothing to that reason ("Failed to connect [Errno 111] ...",
    # then "Repeating...." at every retry).
    assert "Failed to connect" not in out and "Repeating" not in out, out


def test_a_scan_whose_device_answers_again_says_it_goes_on(tmp_path: Path) -> None:
    """After the suspended line nothing said the fault had cleared, and pymodbus' line on the
    silent sensor came again at every poll (13 times in one outage)."""
    rig = tmp_path / "rig.toml"
    err = tmp_path / "stderr.txt"
    with start_sim_rig(SimRigOptions(config_path=rig, time_scale=10.0, settle_s=0.0)) as sim:
        sim.apply_fault("silence:S2:4")  # wall seconds: the scan suspends, then goes on
        with err.open("w") as f:
            proc = subprocess.run(
                [*GONIO, "scan", "--rig", str(rig), "--rotations", "2", "--no-export-fits",
                 "--accept-uncalibrated", "--data-dir", str(tmp_path / "data"),
                 "--no-progress", "-o", str(tmp_path / "x.h5")],
                stdout=subprocess.DEVNULL, stderr=f, env=child_env(), cwd=PROJECT_ROOT,
                timeout=240)
    out = err.read_text()
    assert proc.returncode == 0, out
    suspended = out.find("job 1 suspended: S2")
    resumed = out.find("job 1 resumed: the device answers again; measuring goes on")
    assert 0 <= suspended < resumed, out
    pymodbus = [ln for ln in out.splitlines() if ln.endswith("(pymodbus; the driver reports "
                                                           "the fault)")]
    assert len(pymodbus) == len(set(pymodbus)), out
