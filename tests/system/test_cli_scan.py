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
