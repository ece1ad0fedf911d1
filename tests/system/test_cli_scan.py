"""``gonio scan --sim`` as a user runs it: calibrated on a white reference, then measured."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from gonio.brdf.geometry import lab_to_specimen
from gonio.cli import main
from gonio.results import read_result
from gonio.sim.rig import default_material

pytestmark = pytest.mark.timeout(240)


def test_sim_scan_is_calibrated_and_matches_the_material(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "scan.h5"
    argv = ["scan", "--sim", "--rotations", "4", "--time-scale", "10", "--no-progress",
            "-o", str(out)]
    assert main(argv) == 0
    captured = capsys.readouterr()
    assert "calibrating the simulated rig" in captured.err
    assert "in 1/sr" in captured.out
    res = read_result(out)
    assert "white reference" in res.samples.calibration["source"]
    s = res.samples
    alpha = np.deg2rad(s.stage_angles_deg)[None, :]
    wi = lab_to_specimen(np.asarray(s.light_dirs)[:, None, :], alpha)
    wo = lab_to_specimen(np.asarray(s.sensor_dirs)[:, None, :], alpha)
    truth = default_material().eval(wi.reshape(-1, 3), wo.reshape(-1, 3)).reshape(s.values.shape)
    # Calibrated on the white reference, the measured values are the specimen's BRDF (1/sr)
    # up to the simulated sensor noise.
    rel = np.abs(s.values - truth) / np.maximum(truth, 0.05 * truth.max())
    assert float(np.median(rel)) < 0.05


def test_rig_config_calibration_is_used_until_a_calibration_job_replaces_it(
    tmp_path: Path,
) -> None:
    from gonio.calibration import CALIBRATION_FILE, Calibration, calibration_in_effect
    from gonio.config import load_rig_config

    text = Path("deploy/rig.example.toml").read_text()
    rig = tmp_path / "rig.toml"
    rig.write_text(text + '\n[[calibration.factors]]\nlight = "L1"\nsensor = "S1"\n'
                   'factor = [2.1e-5, 1.9e-5, 2.4e-5]\n')
    cfg = load_rig_config(rig)
    data = tmp_path / "data"
    assert calibration_in_effect(data, load_rig_config("deploy/rig.example.toml")).source == "none"
    from_config = calibration_in_effect(data, cfg)
    assert from_config.source == "rig config"
    assert [p.light for p in from_config.pairs] == ["L1"]
    # A calibration job's factors, once written, take over from the rig config.
    data.mkdir()
    job_cal = Calibration(source="job 7: white reference")
    (data / CALIBRATION_FILE).write_text(job_cal.model_dump_json())
    assert calibration_in_effect(data, cfg).source == "job 7: white reference"


def test_white_reference_calibration_then_a_calibrated_scan(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The lab workflow on a rig config: calibrate on the reference, then scan with it."""
    from gonio.sim.rig import SimRigOptions, start_sim_rig

    rig = tmp_path / "rig.toml"
    with start_sim_rig(SimRigOptions(time_scale=10.0, settle_s=0.0, config_path=rig)) as sim:
        sim.place_white_reference(0.99)
        cal_h5 = tmp_path / "white.h5"
        assert main(["scan", "--rig", str(rig), "--white-reference", "0.99", "--rotations", "2",
                     "--no-progress", "-o", str(cal_h5)]) == 0
        cal_json = tmp_path / "white.calibration.json"
        assert f"--calibration {cal_json}" in capsys.readouterr().out
        sim.place_specimen(default_material())
        out = tmp_path / "scan.h5"
        assert main(["scan", "--rig", str(rig), "--calibration", str(cal_json), "--rotations",
                     "4", "--no-progress", "-o", str(out)]) == 0
        assert "in 1/sr" in capsys.readouterr().out
        s = read_result(out).samples
        truth = np.stack([[sim.true_brdf(a, b, ang) for ang in s.stage_angles_deg]
                          for a, b in s.pairs])
        rel = np.abs(s.values - truth) / np.maximum(truth, 0.05 * truth.max())
        assert float(np.median(rel)) < 0.05


@pytest.mark.parametrize(
    ("extra", "words"),
    [
        (["--white-reference", "1.5"], "albedo, in (0, 1]"),
        (["--white-reference", "0.99", "--adaptive"], "takes no --adaptive"),
    ],
)
def test_bad_white_reference_requests(
    extra: list[str], words: str, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = ["scan", "--rig", "deploy/rig.example.toml", *extra, "-o", "unused.h5"]
    assert main(argv) == 2
    assert words in capsys.readouterr().err
