"""``gonio stage`` against the simulated rig through the real stage drivers."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from gonio.cli import main
from gonio.sim.rig import SimRigOptions, start_sim_rig

pytestmark = pytest.mark.timeout(120)


def _reported_angle(out: str) -> float:
    match = re.search(r"stage at (-?[0-9.]+) deg", out)
    assert match, out
    return float(match.group(1))


@pytest.mark.parametrize("stage", ["dynamixel", "zaber"])
def test_move_and_zero_the_stage(
    stage: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    cfg = tmp_path / "rig.toml"
    with start_sim_rig(SimRigOptions(stage=stage, time_scale=20.0, settle_s=0.0,  # type: ignore[arg-type]
                                     config_path=cfg)) as sim:
        assert main(["stage", "--rig", str(cfg), "move", "30"]) == 0
        assert _reported_angle(capsys.readouterr().out) == pytest.approx(30.0, abs=0.1)
        assert sim.motion.position_deg() == pytest.approx(30.0, abs=0.2)
        assert main(["stage", "--rig", str(cfg), "home"]) == 0
        out = capsys.readouterr().out
        assert _reported_angle(out) == pytest.approx(0.0, abs=0.1) and " homed" in out
        # The zero survives a new connection: it lives in the device, not in the process, and
        # so does the fact that it was set.
        assert main(["stage", "--rig", str(cfg), "status"]) == 0
        out = capsys.readouterr().out
        assert _reported_angle(out) == pytest.approx(0.0, abs=0.1)
        assert "idle, homed" in out
        # Stop and clear-faults on an idle stage leave it idle (and homed).
        for action in ("stop", "clear-faults"):
            assert main(["stage", "--rig", str(cfg), action]) == 0
            assert "idle, homed, faults: none" in capsys.readouterr().out


@pytest.mark.parametrize("stage", ["dynamixel", "zaber"])
def test_a_fresh_stage_homed_at_power_up_position_says_homed(
    stage: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    cfg = tmp_path / "rig.toml"
    with start_sim_rig(SimRigOptions(stage=stage, time_scale=20.0, settle_s=0.0,  # type: ignore[arg-type]
                                     config_path=cfg)):
        assert main(["stage", "--rig", str(cfg), "status"]) == 0
        assert "not homed" in capsys.readouterr().out
        # Zeroed where it powered up (a Homing Offset of 0 on the Dynamixel): still homed.
        assert main(["stage", "--rig", str(cfg), "home"]) == 0
        capsys.readouterr()
        assert main(["stage", "--rig", str(cfg), "status"]) == 0
        assert "idle, homed" in capsys.readouterr().out


@pytest.mark.parametrize(
    ("argv", "words"),
    [
        (["move"], "needs a target angle"),
        (["move", "1e6"], "outside the travel limits"),
        (["home", "5"], "takes no angle"),
        (["move", "nan"], "'move' needs a finite angle in degrees, got nan"),
    ],
)
def test_bad_stage_commands_are_refused_before_connecting(
    argv: list[str], words: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # The config points at a port nobody serves: the refusal must come before any connect.
    cfg = tmp_path / "rig.toml"
    cfg.write_text(Path("deploy/rig.example.toml").read_text())
    assert main(["stage", "--rig", str(cfg), *argv]) == 2
    assert words in capsys.readouterr().err


def test_a_nan_target_through_a_daemon_is_refused_in_words(
    capsys: pytest.CaptureFixture[str]
) -> None:
    """Through a daemon a NaN reached the JSON encoder: "Out of range float values are not
    JSON compliant". Refused before any request (nothing listens on port 9)."""
    assert main(["stage", "--daemon", "http://127.0.0.1:9", "move", "nan"]) == 2
    err = capsys.readouterr().err
    assert "needs a finite angle" in err and "JSON" not in err, err


def test_missing_rig_config_is_a_clear_error(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["stage", "--rig", str(tmp_path / "nope.toml"), "status"]) == 2
    assert "nope.toml" in capsys.readouterr().err


def test_a_move_a_stop_cut_short_is_no_success_through_a_daemon(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """The daemon answers a move that a stop (the page's Stop) cut short with where it
    stopped, in ``note``: printed as a plain position, exit 0, a script took the stage to be
    at its target. The daemon's answer stands in for its HTTP reply here."""
    import gonio.cli.stage_command as stage_command

    class Answer:
        def __init__(self, *args: object, **kwargs: object) -> None:
            pass

        def __enter__(self) -> Answer:
            return self

        def __exit__(self, *exc: object) -> None:
            pass

        def request(self, method: str, path: str, **kwargs: object) -> dict[str, object]:
            return {"position_deg": 12.5, "moving": False, "homed": True, "faults": [],
                    "note": "stopped by a stop command before it ended: at 12.500 deg, "
                            "short of 90 deg"}

    monkeypatch.setattr(stage_command, "DaemonClient", Answer)
    assert main(["stage", "--daemon", "http://127.0.0.1:9", "move", "90"]) == 1
    err = capsys.readouterr().err
    assert "move stopped by a stop command before it ended: at 12.500 deg, short of 90 deg" \
        in err, err
    assert "stage at 12.500 deg" in err, err
