"""A lamp never outlives the daemon that switched it on.

Two independent guards, each tested against the simulated lamp controllers over Modbus TCP with
a daemon child process killed by SIGKILL while a lamp is on: the controller's communication
watchdog (armed by the driver, fed while a lamp is on) and ``gonio rig lights-off``, which the
systemd unit runs after the daemon exits (``ExecStopPost=``).
"""

from __future__ import annotations

import signal
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from gonio.sim.rig import SimRig, SimRigOptions, start_sim_rig
from gonio.store import JobStore
from tests.system.daemon_proc import DaemonProcess, gonio, start_daemon, wait_for

pytestmark = [pytest.mark.system, pytest.mark.timeout(300)]

WATCHDOG_S = 0.5
LONG_EXPOSURE_S = 1.5  # three watchdog periods with the lamp on: the driver must feed it


def _sim(tmp_path: Path, watchdog: float | None) -> SimRig:
    # Real time (time_scale 1): exposures and the watchdog run on the same clock. Dim lamps:
    # second-long exposures of the default ones would saturate the 20-bit sensors.
    sim = start_sim_rig(SimRigOptions(time_scale=1.0, settle_s=0.0, lamp_watchdog_s=watchdog,
                                      irradiance=5e4, config_path=tmp_path / "rig.toml"))
    sim.place_white_reference()  # the jobs here are calibrations (no basis needed)
    return sim


@pytest.fixture
def watched(tmp_path: Path) -> Iterator[SimRig]:
    with _sim(tmp_path, WATCHDOG_S) as s:
        yield s


@pytest.fixture
def unwatched(tmp_path: Path) -> Iterator[SimRig]:
    with _sim(tmp_path, None) as s:
        yield s


def _lamps_on(sim: SimRig) -> list[str]:
    assert sim.modbus is not None
    return [n for n, (on, _, _) in sim.modbus.snapshot()["lamps"].items() if on]


def _trips(sim: SimRig) -> int:
    assert sim.modbus is not None
    return sum(t for _, t in sim.modbus.snapshot()["watchdogs"].values())


def _kill_with_a_lamp_on(sim: SimRig, data: Path) -> DaemonProcess:
    daemon = start_daemon(["--no-export-fits",
                           "--rig", str(sim.config_path), "--data-dir", str(data),
                           "--port", "0"])
    try:
        with daemon.client() as c:
            plan = {"kind": "calibration", "reference_albedo": 0.99, "rotations": 1,
                    "exposure": {"exposure_s": 3.0, "light_settle_s": 0.0, "dark": "none"}}
            assert c.post("/api/v1/jobs", json={"plan": plan}).status_code == 201
            wait_for(lambda: bool(_lamps_on(sim)), what="a lamp to be switched on")
    finally:
        daemon.stop(signal.SIGKILL)
    return daemon


def test_the_watchdog_switches_the_lamp_off_after_kill_9(watched: SimRig, tmp_path: Path
                                                          ) -> None:
    assert watched.modbus is not None
    _kill_with_a_lamp_on(watched, tmp_path / "data")
    # Nobody sends anything now: the controller's own watchdog is what switches the lamp off.
    wait_for(lambda: not _lamps_on(watched), timeout=30, what="the watchdog to trip")
    assert _trips(watched) >= 1
    armed = {n: w for n, (w, _) in watched.modbus.snapshot()["watchdogs"].items()}
    assert armed == pytest.approx(dict.fromkeys(armed, WATCHDOG_S))  # armed by the driver


def test_a_fed_watchdog_never_cuts_a_long_exposure(watched: SimRig, tmp_path: Path) -> None:
    data = tmp_path / "data"
    daemon = start_daemon(["--no-export-fits",
                           "--rig", str(watched.config_path), "--data-dir", str(data),
                           "--port", "0"])
    try:
        with daemon.client() as c:
            plan = {"kind": "calibration", "reference_albedo": 0.99, "rotations": 1,
                    "exposure": {"exposure_s": LONG_EXPOSURE_S, "light_settle_s": 0.0,
                                 "dark": "none"}}
            job = c.post("/api/v1/jobs", json={"plan": plan}).json()["id"]
            wait_for(lambda: c.get(f"/api/v1/jobs/{job}").json()["state"] in (
                "completed", "failed"), what="the job")
            row = c.get(f"/api/v1/jobs/{job}").json()
            assert row["state"] == "completed", row["reason"]
    finally:
        daemon.stop()
    assert _trips(watched) == 0
    readings = JobStore(data / "gonio.sqlite", durable=False).readings(job)
    measured = np.array([r.raw for r in readings])
    expected = np.array([
        watched.true_brdf(r.light, r.sensor, r.actual_deg)
        * watched.expected_counts_per_brdf(r.light, r.sensor, r.exposure_s) for r in readings])
    # The lamp shone for the whole exposure (a cut lamp would read a fraction of it); the
    # remaining difference is the simulated dark signal and noise.
    dark = watched.noise.dark_offset + watched.noise.dark_rate * LONG_EXPOSURE_S
    assert np.allclose(measured - dark, expected, rtol=0.05, atol=0.01 * expected.max())


def test_lights_off_after_the_daemon_died(unwatched: SimRig, tmp_path: Path) -> None:
    _kill_with_a_lamp_on(unwatched, tmp_path / "data")
    lit = _lamps_on(unwatched)
    time.sleep(2 * WATCHDOG_S)
    assert _lamps_on(unwatched) == lit  # no watchdog here: it would stay on
    done = gonio(["rig", "lights-off", "--rig", str(unwatched.config_path)])
    assert done.returncode == 0, done.stderr
    assert "lights off: L1, L2, L3" in done.stdout
    assert _lamps_on(unwatched) == []


def test_lights_off_is_refused_while_a_daemon_owns_the_rig(unwatched: SimRig, tmp_path: Path
                                                           ) -> None:
    daemon = start_daemon(["--no-export-fits", "--rig", str(unwatched.config_path), "--data-dir",
                           str(tmp_path / "data"), "--port", "0"])
    try:
        refused = gonio(["rig", "lights-off", "--rig", str(unwatched.config_path)])
    finally:
        daemon.stop()
    assert refused.returncode == 2
    assert f"pid {daemon.pid}" in refused.stderr and "halt" in refused.stderr


def test_lights_off_reads_the_rig_from_the_daemon_config(unwatched: SimRig, tmp_path: Path
                                                         ) -> None:
    cfg = tmp_path / "daemon.toml"
    cfg.write_text(f'[paths]\nrig_config = "{unwatched.config_path}"\n')
    done = gonio(["rig", "lights-off", "--config", str(cfg)])
    assert done.returncode == 0, done.stderr
    cfg.write_text("[paths]\n")
    missing = gonio(["rig", "lights-off", "--config", str(cfg)])
    assert missing.returncode == 2 and "sets no [paths] rig_config" in missing.stderr
