"""What is on the simulated stage: swapped over Modbus by 'gonio sim-place', and a calibration
on anything but the white reference fails loudly."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from gonio.cli import main
from gonio.sim.rig import SimRigOptions, default_material, start_sim_rig

pytestmark = [pytest.mark.system, pytest.mark.timeout(240)]


def test_sim_place_swaps_what_the_sensors_see(tmp_path: Path,
                                              capsys: pytest.CaptureFixture[str]) -> None:
    rig = tmp_path / "rig.toml"
    with start_sim_rig(SimRigOptions(noise=None, config_path=rig)) as sim:
        specimen = sim.true_brdf("L1", "S1", 30.0)
        np.testing.assert_allclose(
            specimen, default_material().eval(*_specimen_dirs(sim, "L1", "S1", 30.0)))
        assert main(["sim-place", "white", "--albedo", "0.8", "--rig", str(rig)]) == 0
        assert "holds the white reference (albedo 0.8)" in capsys.readouterr().out
        assert sim.on_stage == "white reference"
        np.testing.assert_allclose(sim.true_brdf("L2", "S3", 77.0), 0.8 / math.pi)
        assert main(["sim-place", "show", "--rig", str(rig)]) == 0
        assert "white reference" in capsys.readouterr().out
        assert main(["sim-place", "specimen", "--rig", str(rig)]) == 0
        assert "holds the specimen" in capsys.readouterr().out
        np.testing.assert_allclose(sim.true_brdf("L1", "S1", 30.0), specimen)
        assert main(["sim-place", "specimen", "--albedo", "0.5", "--rig", str(rig)]) == 2
        assert "--albedo goes with 'white'" in capsys.readouterr().err
    # Nothing listens any more: a clear error, not a traceback.
    assert main(["sim-place", "white", "--rig", str(rig)]) == 2
    assert "no simulated rig answers" in capsys.readouterr().err


def _specimen_dirs(sim: object, light: str, sensor: str, deg: float) -> tuple[np.ndarray, ...]:
    from gonio.brdf.tables.geometry import lab_to_specimen

    cfg = sim.config  # type: ignore[attr-defined]
    wi = np.asarray(cfg.light(light).direction.vector())
    wo = np.asarray(cfg.sensor(sensor).direction.vector())
    return lab_to_specimen(wi, math.radians(deg)), lab_to_specimen(wo, math.radians(deg))


def test_calibration_on_the_specimen_fails_and_writes_no_factors(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    rig = tmp_path / "rig.toml"
    data = tmp_path / "data"
    with start_sim_rig(SimRigOptions(time_scale=10.0, settle_s=0.0, config_path=rig)):
        # The user forgot to put the white reference on the stage.
        code = main(["scan", "--no-export-fits",
                     "--rig", str(rig), "--white-reference", "0.99", "--rotations", "4",
                     "--data-dir", str(data), "--no-progress", "-o", str(tmp_path / "w.h5")])
    assert code == 1
    err = capsys.readouterr().err
    assert "calibration refused: the reference does not read like a white diffuser" in err
    assert "gonio sim-place white" in err
    assert not (data / "calibration.json").exists()
    assert not (tmp_path / "w.calibration.json").exists() and not (tmp_path / "w.h5").exists()


def test_sim_scan_with_white_reference_puts_the_reference_on_itself(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from gonio.calibration import Calibration
    from gonio.results import read_result

    out = tmp_path / "w.h5"
    assert main(["scan", "--no-export-fits",
                 "--sim", "--white-reference", "0.9", "--rotations", "4",
                 "--time-scale", "10", "--data-dir", str(tmp_path / "d"), "--no-progress",
                 "-o", str(out)]) == 0
    cal = Calibration.model_validate_json((tmp_path / "w.calibration.json").read_text())
    for r in read_result(out).readings:
        value = cal.factor(r.light, r.sensor, 3) * np.subtract(r.raw, r.dark)
        np.testing.assert_allclose(value, 0.9 / math.pi, rtol=0.05)
