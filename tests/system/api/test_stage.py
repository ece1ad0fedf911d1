"""Manual stage commands through the API: commissioning and specimen loading."""

from __future__ import annotations

import pytest

from tests.system.api.conftest import Daemon

pytestmark = pytest.mark.timeout(120)


def test_move_then_home_sets_the_zero_on_the_real_driver(daemon: Daemon) -> None:
    with daemon.client() as c:
        r = c.post("/api/v1/rig/stage", json={"action": "move", "angle_deg": 40.0})
        assert r.status_code == 200, r.text
        assert r.json()["position_deg"] == pytest.approx(40.0, abs=0.2)
        # The simulated motor really turned: its physics model agrees with the driver.
        assert daemon.sim.motion.position_deg() == pytest.approx(40.0, abs=0.2)

        r = c.post("/api/v1/rig/stage", json={"action": "home"})
        assert r.status_code == 200, r.text
        assert r.json()["position_deg"] == pytest.approx(0.0, abs=0.2)
        assert r.json()["homed"] is True

        # Going back to the old zero is now a move to -40 deg.
        r = c.post("/api/v1/rig/stage", json={"action": "move", "angle_deg": -40.0})
        assert r.status_code == 200, r.text
        assert daemon.sim.motion.position_deg() == pytest.approx(0.0, abs=0.2)
        c.post("/api/v1/rig/stage", json={"action": "home"}).raise_for_status()
        # The queue is free again afterwards.
        assert c.get("/api/v1/rig").json()["queue_held"] is None


@pytest.mark.parametrize(
    ("body", "status", "words"),
    [
        ({"action": "move"}, 422, "needs angle_deg"),
        ({"action": "move", "angle_deg": 1e6}, 422, "outside the stage's travel limits"),
        ({"action": "spin"}, 422, "action"),
        ({"action": "move", "angle_deg": 10, "speed": 3}, 422, "speed"),
    ],
)
def test_bad_stage_requests_are_refused_before_anything_moves(
    daemon: Daemon, body: dict[str, object], status: int, words: str
) -> None:
    before = daemon.sim.motion.position_deg()
    with daemon.client() as c:
        r = c.post("/api/v1/rig/stage", json=body)
    assert r.status_code == status, r.text
    assert words in r.text
    assert daemon.sim.motion.position_deg() == pytest.approx(before, abs=1e-6)


def test_stage_commands_need_a_key(daemon: Daemon) -> None:
    with daemon.client(key=None) as c:
        assert c.post("/api/v1/rig/stage", json={"action": "stop"}).status_code == 401


def test_the_stage_is_not_moved_by_hand_under_a_running_job(daemon: Daemon) -> None:
    from tests.system.api.test_scan_flow import scan, wait_state

    with daemon.client() as c:
        job = c.post("/api/v1/jobs", json=scan("busy", rotations=36)).json()["id"]
        wait_state(c, job, {"running"})
        r = c.post("/api/v1/rig/stage", json={"action": "move", "angle_deg": 10.0})
        assert r.status_code == 409, r.text
        assert f"job {job} is running" in r.text
        assert c.post(f"/api/v1/jobs/{job}/abort").status_code == 200
        wait_state(c, job, {"aborted"})
        # Once the job has ended, manual moves work again.
        r = c.post("/api/v1/rig/stage", json={"action": "move", "angle_deg": 10.0})
        assert r.status_code == 200, r.text


def test_gonio_stage_through_the_daemon(
    daemon: Daemon, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    from gonio.cli import main

    monkeypatch.delenv("GONIO_API_KEY", raising=False)
    base = ["stage", "--daemon", daemon.url]
    # A change without a key is refused, saying how to give one; nothing moved.
    before = daemon.sim.motion.position_deg()
    assert main([*base, "move", "25"]) == 2
    err = capsys.readouterr().err
    assert "needs an API key" in err and "--api-key" in err and "GONIO_API_KEY" in err
    assert daemon.sim.motion.position_deg() == pytest.approx(before, abs=1e-6)

    monkeypatch.setenv("GONIO_API_KEY", daemon.key)
    assert main([*base, "move", "25"]) == 0
    reported = float(capsys.readouterr().out.split()[2])
    assert reported == pytest.approx(25.0, abs=0.2)  # the encoder reading (0.088 deg counts)
    assert daemon.sim.motion.position_deg() == pytest.approx(25.0, abs=0.2)
    assert main([*base, "home"]) == 0
    assert main([*base, "status"]) == 0  # reads need no key here; the key is sent anyway
    out = capsys.readouterr().out.splitlines()
    assert out[-1].startswith("stage at 0.000 deg, idle, homed")
    for action in ("stop", "clear-faults"):  # an idle stage stays idle, homed
        assert main([*base, action]) == 0
        assert "idle, homed, faults: none" in capsys.readouterr().out


def test_gonio_stage_daemon_errors_are_one_line(
    daemon: Daemon, capsys: pytest.CaptureFixture[str]
) -> None:
    from gonio.cli import main

    assert main(["stage", "--daemon", daemon.url, "--api-key", daemon.key, "move", "1e6"]) == 2
    assert "outside the stage's travel limits" in capsys.readouterr().err
    assert main(["stage", "--daemon", "http://127.0.0.1:9", "status"]) == 2
    assert "cannot reach the daemon at http://127.0.0.1:9" in capsys.readouterr().err
    assert main(["stage", "--daemon", "localhost:8600", "status"]) == 2
    assert "give the daemon's address" in capsys.readouterr().err
