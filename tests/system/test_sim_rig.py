"""A whole simulated rig driven by the real drivers: readings come back as the material's BRDF."""

from __future__ import annotations

import argparse
import asyncio
import importlib.util
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from gonio.cli import COMMAND_MODULES, UsageError, sim_command
from gonio.config import load_rig_config
from gonio.drivers.factory import build_rig
from gonio.hal import DeviceUnavailable
from gonio.sim.rig import SimRigOptions, start_sim_rig

pytestmark = pytest.mark.system

EXPOSURE_S = 0.005
ANGLES = (0.0, 95.0, 230.0)


def _stage_params() -> list[Any]:
    zaber_ready = importlib.util.find_spec("gonio.drivers.zaber") is not None
    return [
        "dynamixel",
        pytest.param(
            "zaber",
            marks=pytest.mark.skipif(not zaber_ready, reason="Zaber driver not in the tree yet"),
        ),
    ]


async def _measure(rig: Any, sim: Any) -> list[tuple[str, str, float, Any, Any]]:
    """Readings of every pair at a few angles, as the engine takes them (one lamp at a time)."""
    out = []
    async with rig:
        await rig.stage.home()
        for angle in ANGLES:
            reached = await rig.stage.move_to(angle)
            assert reached == pytest.approx(angle, abs=0.1)
            dark = {name: await s.read(EXPOSURE_S, averages=4) for name, s in rig.sensors.items()}
            for lname, light in rig.lights.items():
                await light.set_on(True)
                readings = await asyncio.gather(*(s.read(EXPOSURE_S) for s in rig.sensors.values()))
                await light.set_on(False)
                for sname, r in zip(rig.sensors, readings, strict=True):
                    out.append((lname, sname, reached, r, dark[sname]))
    return out


@pytest.mark.parametrize("stage", _stage_params())
def test_measured_values_convert_back_to_the_material(stage: str) -> None:
    with start_sim_rig(SimRigOptions(stage=stage, time_scale=20.0, seed=5)) as sim:
        rig = build_rig(sim.config)
        rows = asyncio.run(asyncio.wait_for(_measure(rig, sim), 60))

    assert len(rows) == len(ANGLES) * 3 * 4
    checked = strong = 0
    for lname, sname, angle, reading, dark in rows:
        assert not dark.saturated
        if reading.saturated:
            continue
        per_brdf = sim.expected_counts_per_brdf(lname, sname, EXPOSURE_S)
        measured = (np.array(reading.values) - np.array(dark.values)) / per_brdf
        truth = sim.true_brdf(lname, sname, angle)
        # Noise model: shot + read noise of the reading, plus the 4-average dark's read noise.
        signal = truth * per_brdf
        sigma_counts = np.sqrt(
            sim.noise.sigma(signal, EXPOSURE_S) ** 2
            + sim.noise.sigma(0, EXPOSURE_S) ** 2 / 4
            + 1 / 6
        )
        tol = 5 * sigma_counts / per_brdf
        assert np.all(np.abs(measured - truth) <= tol), (lname, sname, angle, measured, truth)
        checked += 1
        strong += int(np.all(signal > 50 * sigma_counts))
    assert checked >= 30
    assert strong >= 10  # the comparison is not all noise


def test_anisotropic_material_changes_with_stage_angle() -> None:
    """The default material is anisotropic: the same pair sees different values when turned."""
    with start_sim_rig(SimRigOptions(noise=None)) as sim:
        values = [sim.true_brdf("L1", "S1", a)[0] for a in (0.0, 45.0, 90.0)]
    assert max(values) > 1.05 * min(values)


def test_device_fault_from_the_options_reaches_the_driver() -> None:
    async def run(sim: Any) -> None:
        rig = build_rig(sim.config)
        sensor = rig.sensors["S2"]
        with pytest.raises(DeviceUnavailable):
            await sensor.connect()
        sim.clear_faults()
        await sensor.connect()
        await sensor.close()

    with start_sim_rig(SimRigOptions(faults=["silence:S2"])) as sim:
        asyncio.run(asyncio.wait_for(run(sim), 10))


def test_bad_options_and_faults_have_clear_messages() -> None:
    with pytest.raises(ValueError, match=r"theta 95\.0 deg: must be in"):
        start_sim_rig(SimRigOptions(lights=[(95.0, 0.0)]))
    with start_sim_rig(SimRigOptions()) as sim:
        with pytest.raises(ValueError, match="not understood; faults are: silence:NAME"):
            sim.apply_fault("explode:S1")
        with pytest.raises(ValueError, match="no simulated device named 'S9'"):
            sim.apply_fault("silence:S9")
        with pytest.raises(ValueError, match="could not convert"):
            sim.apply_fault("lamp-drift:L1:lots")


def _sim_cli(argv: list[str]) -> int:
    """Run ``gonio sim`` through its own parser (other commands may not be importable yet)."""
    parser = argparse.ArgumentParser(prog="gonio")
    sim_command.register(parser.add_subparsers(dest="command"))
    args = parser.parse_args(["sim", *argv])
    return int(args.func(args))


def test_cli_writes_a_loadable_config(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert "gonio.cli.sim_command" in COMMAND_MODULES
    out = tmp_path / "rig.toml"
    code = _sim_cli(
        [
            "--stage",
            "zaber",
            "--zaber-transport",
            "tcp",
            "-o",
            str(out),
            "--duration",
            "0.2",
            "--noise",
            "read=3,shot=0.2",
        ]
    )
    assert code == 0
    cfg = load_rig_config(out)
    assert cfg.stage.driver == "zaber" and cfg.stage.port.startswith("socket://127.0.0.1:")
    assert str(out) in capsys.readouterr().out


def test_cli_refuses_bad_faults_and_noise() -> None:
    with pytest.raises(ValueError, match="fault 'melt' is not understood"):
        _sim_cli(["--fault", "melt", "--duration", "0"])
    with pytest.raises(UsageError, match="--noise: 'loud' is not key=value"):
        _sim_cli(["--noise", "loud", "--duration", "0"])
    with pytest.raises(UsageError, match="--noise: read='x' is not a number"):
        _sim_cli(["--noise", "read=x", "--duration", "0"])


def test_material_by_library_name_and_a_clear_error_for_a_typo() -> None:
    from gonio.brdf.materials.library import get_material
    from gonio.brdf.models.analytic import Lambert

    model = get_material("brushed-metal-004")
    with start_sim_rig(SimRigOptions(material="brushed-metal-004", noise=None)) as sim:
        wi = np.asarray(sim.config.light("L2").direction.vector())
        wo = np.asarray(sim.config.sensor("S1").direction.vector())
        np.testing.assert_allclose(sim.true_brdf("L2", "S1", 0.0), model.eval(wi, wo))
    with pytest.raises(ValueError, match="did you mean brushed-metal-004"):
        start_sim_rig(SimRigOptions(material="brushd-metal-004"))
    # A model object is used as given.
    with start_sim_rig(SimRigOptions(material=Lambert(0.3), noise=None)) as sim:
        np.testing.assert_allclose(sim.true_brdf("L1", "S4", 10.0), 0.3 / np.pi)
