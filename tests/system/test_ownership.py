"""One owner per data directory and per rig, with real processes on the simulated rig.

The rig simulators run in this test process; daemons and CLI commands run as child processes
with the real drivers, exactly as on a lab PC: a second daemon on a data directory in use, and a
CLI command on a rig a daemon owns, are refused naming the owner, and the daemon's job is not
disturbed.
"""

from __future__ import annotations

import json
import re
import signal
import sys
from collections.abc import Iterator
from pathlib import Path

import httpx
import numpy as np
import pytest

from gonio.sim.rig import SimRig, SimRigOptions, start_sim_rig
from gonio.store import JobStore
from tests.system.daemon_proc import DaemonProcess, gonio, start_daemon, wait_for

pytestmark = [pytest.mark.system, pytest.mark.timeout(300)]

EXPOSURE_S = 0.02


@pytest.fixture
def sim(tmp_path: Path) -> Iterator[SimRig]:
    with start_sim_rig(SimRigOptions(time_scale=10.0, settle_s=0.0,
                                     config_path=tmp_path / "rig.toml")) as s:
        s.place_white_reference()  # the daemons here run calibration jobs (no basis needed)
        yield s


@pytest.fixture
def other_sim(tmp_path: Path) -> Iterator[SimRig]:
    with start_sim_rig(SimRigOptions(stage="zaber", time_scale=10.0, settle_s=0.0,
                                     config_path=tmp_path / "rig2.toml")) as s:
        yield s


def _serve(sim: SimRig, data_dir: Path) -> DaemonProcess:
    return start_daemon(["--rig", str(sim.config_path), "--data-dir", str(data_dir),
                         "--port", "0"])


def test_second_daemon_and_scan_on_a_data_dir_in_use_are_refused(
    sim: SimRig, other_sim: SimRig, tmp_path: Path
) -> None:
    data = tmp_path / "data"
    first = _serve(sim, data)
    try:
        # Another rig, same data directory: refused for the directory, naming the first daemon.
        second = gonio(["serve", "--rig", str(other_sim.config_path), "--data-dir", str(data),
                        "--port", "0"])
        assert second.returncode == 2, second.stdout + second.stderr
        assert "data directory" in second.stderr and f"pid {first.pid}" in second.stderr
        assert "gonio serve" in second.stderr  # the holder's program
        # Its advice names only options gonio serve has (it advised --db, which serve lacks).
        _assert_advice_fits(second.stderr, "serve", "--data-dir")
        scan = gonio(["scan", "--no-export-fits", "--rig", str(other_sim.config_path), "--db",
                      str(data / "gonio.sqlite"), "--rotations", "2", "-o",
                      str(tmp_path / "x.h5")])
        assert scan.returncode == 2, scan.stdout + scan.stderr
        assert f"pid {first.pid}" in scan.stderr
        _assert_advice_fits(scan.stderr, "scan", "--db")
        assert not (tmp_path / "x.h5").exists()
        with first.client() as c:
            assert c.get("/health").json()["status"] == "ok"  # the first one is unharmed
    finally:
        # kill -9: the kernel drops the lock; the file left behind must not block the next one.
        first.stop(signal.SIGKILL)
    again = _serve(other_sim, data)
    try:
        with again.client() as c:
            assert c.get("/health").status_code == 200
    finally:
        # uvicorn re-raises SIGTERM after its graceful shutdown: systemd counts that as clean.
        assert again.stop() in (0, -signal.SIGTERM)


def _assert_advice_fits(refusal: str, command: str, must_name: str) -> None:
    """Every ``--option`` a refusal advises is one ``gonio COMMAND --help`` lists, and it names
    ``must_name``: the advice is one the user can follow with that command."""
    listed = set(re.findall(r"--[a-z][a-z-]+", gonio([command, "--help"]).stdout))
    advised = set(re.findall(r"--[a-z][a-z-]+", refusal))
    assert must_name in advised, refusal
    assert advised <= listed, (advised - listed, refusal)


def _expected_counts(sim: SimRig, r: object) -> float:
    """Independent expectation of one reading: the simulator's physics, not the driver's."""
    light, sensor = r.light, r.sensor  # type: ignore[attr-defined]
    brdf = sim.true_brdf(light, sensor, r.actual_deg)  # type: ignore[attr-defined]
    return brdf * sim.expected_counts_per_brdf(light, sensor, r.exposure_s)  # type: ignore[attr-defined, no-any-return]


def test_cli_on_a_rig_the_daemon_owns_is_refused_and_the_job_is_unharmed(
    sim: SimRig, tmp_path: Path
) -> None:
    data = tmp_path / "data"
    daemon = _serve(sim, data)
    rotations = 8
    try:
        with daemon.client() as c:
            plan = {"kind": "calibration", "reference_albedo": 0.99, "rotations": rotations,
                    "exposure": {"exposure_s": EXPOSURE_S, "light_settle_s": 0.0}}
            r = c.post("/api/v1/jobs", json={"plan": plan})
            assert r.status_code == 201, r.text
            job = r.json()["id"]
            wait_for(lambda: c.get(f"/api/v1/jobs/{job}").json()["done_angles"] >= 1,
                     what="the daemon's job to measure its first angle")
            # While it measures: a manual move and a foreground scan on the same rig.
            move = gonio(["stage", "--rig", str(sim.config_path), "move", "10"])
            scan = gonio(["scan", "--no-export-fits",
                          "--rig", str(sim.config_path), "--rotations", "2", "-o",
                          str(tmp_path / "cli.h5")])
            assert c.get(f"/api/v1/jobs/{job}").json()["state"] in ("running", "completed",
                                                                     "reconstructing")
            wait_for(lambda: c.get(f"/api/v1/jobs/{job}").json()["state"] in (
                "completed", "failed", "aborted"), what="the daemon's job to end")
            final = c.get(f"/api/v1/jobs/{job}").json()
    finally:
        status = daemon.stop()
    assert move.returncode != 0 and scan.returncode == 2
    for refused in (move, scan):
        assert "in use by" in refused.stderr and f"pid {daemon.pid}" in refused.stderr, (
            refused.stderr)
        assert "obstruction" not in refused.stderr
        # and how to act on the rig instead, at the daemon's real address (not a default port)
        assert f"--daemon {daemon.url}" in refused.stderr, refused.stderr
    assert not (tmp_path / "cli.h5").exists()
    assert final["state"] == "completed", final
    assert status in (0, -signal.SIGTERM)
    readings = JobStore(data / "gonio.sqlite", durable=False).readings(job)
    assert len(readings) == rotations * 12
    measured = np.array([np.subtract(r.raw, r.dark) for r in readings])
    expected = np.array([_expected_counts(sim, r) for r in readings])
    # Every reading is the simulator's physics up to its sensor noise: no angle was measured
    # with the stage moved under it or a lamp switched by another program.
    assert np.allclose(measured, expected, rtol=0.05, atol=0.01 * expected.max())
    # With the daemon gone the rig is free again.
    free = gonio(["stage", "--rig", str(sim.config_path), "status"])
    assert free.returncode == 0, free.stderr


def test_a_dead_worker_fails_health_and_the_daemon_exits_non_zero(
    sim: SimRig, tmp_path: Path
) -> None:
    script = Path(__file__).with_name("_dying_daemon.py")
    daemon = start_daemon(["--rig", str(sim.config_path), "--data-dir", str(tmp_path / "d"),
                           "--port", "0"], command=[sys.executable, str(script)])
    try:
        with daemon.client() as c:
            plan = {"kind": "uniform", "rotations": 2}
            assert c.post("/api/v1/jobs", json={"plan": plan}).status_code == 201
        # No stall: the process ends by itself, with a failure status a supervisor acts on.
        assert daemon.proc.wait(timeout=60) == 1
    finally:
        daemon.stop()
    assert "job worker died" in daemon.text()
    assert "injected worker failure" in daemon.text()


def test_health_fails_while_the_worker_is_dead(tmp_path: Path) -> None:
    from gonio.api.auth import ApiKeyring
    from gonio.daemon import DaemonConfig, build_app
    from tests.system.api.live_server import live_server

    with start_sim_rig(SimRigOptions(time_scale=10.0, settle_s=0.0)) as s:
        cfg = DaemonConfig().with_overrides(paths__data_dir=str(tmp_path / "d"))
        key = "health-test-key-0123456789"
        app = build_app(cfg, s.config, ApiKeyring({"t": key}))
        service = app.state.service

        async def die(job: object) -> None:
            raise RuntimeError("injected worker failure")

        service.worker.run_job = die
        with live_server(app) as url, httpx.Client(base_url=url, timeout=30,
                                                   headers={"X-API-Key": key}) as c:
            assert c.get("/health").status_code == 200
            assert c.post("/api/v1/jobs", json={"plan": {"kind": "uniform"}}).status_code == 201
            wait_for(lambda: c.get("/health").status_code == 503, timeout=60,
                     what="/health to report the dead worker")
            body = c.get("/health").json()
            assert body["status"] == "failed" and "injected worker failure" in body["error"]


def test_a_key_from_gonio_keys_new_opens_the_daemon(sim: SimRig, tmp_path: Path) -> None:
    keys = tmp_path / "api-keys"
    made = gonio(["keys", "new", "lab", "--keys-file", str(keys)])
    assert made.returncode == 0, made.stderr
    key = made.stdout.strip()
    daemon = start_daemon(["--rig", str(sim.config_path), "--data-dir", str(tmp_path / "d"),
                           "--keys-file", str(keys), "--port", "0"], GONIO_API_KEYS="")
    try:
        with httpx.Client(base_url=daemon.url, timeout=30) as c:
            lock = {"reason": "key check"}
            assert c.put("/api/v1/maintenance", json=lock).status_code == 401
            assert c.put("/api/v1/maintenance", json=lock,
                         headers={"X-API-Key": key + "x"}).status_code == 403
            r = c.put("/api/v1/maintenance", json=lock, headers={"X-API-Key": key})
            assert r.status_code == 200 and r.json()["by"] == "lab"
    finally:
        daemon.stop()
    assert key not in daemon.text()  # logged by name only


def test_gonio_jobs_show_of_a_store_a_daemon_runs_has_the_daemons_live_answer(
    sim: SimRig, tmp_path: Path
) -> None:
    """What only the daemon knows of a measuring job (its ETA counted down by the engine)
    was null in ``gonio jobs show``, which read the store: with a daemon running the store it
    asks that daemon, at the address the store's lock records."""
    data = tmp_path / "data"
    daemon = _serve(sim, data)
    try:
        with daemon.client() as c:
            plan = {"kind": "calibration", "reference_albedo": 0.99, "rotations": 36,
                    "exposure": {"exposure_s": EXPOSURE_S, "light_settle_s": 0.0}}
            job = c.post("/api/v1/jobs", json={"plan": plan}).json()["id"]
            wait_for(lambda: c.get(f"/api/v1/jobs/{job}").json()["done_angles"] >= 1,
                     what="the daemon's job to measure its first angle")
            api = c.get(f"/api/v1/jobs/{job}").json()
            shown = gonio(["jobs", "show", str(job), "--db", str(data / "gonio.sqlite"),
                           "--json"])
            text = gonio(["jobs", "show", str(job), "--db", str(data / "gonio.sqlite")])
            c.post(f"/api/v1/jobs/{job}/abort")
    finally:
        daemon.stop()
    assert shown.returncode == 0, shown.stderr
    got = json.loads(shown.stdout)
    assert api["eta_s"] is not None and got["eta_s"] is not None, (api, got)
    assert got["state"] == "running" and got["done_angles"] >= api["done_angles"]
    assert got.keys() == api.keys()
    assert text.returncode == 0 and "measuring left:" in text.stdout, text.stdout
