"""``gonio scan --sim --exposure T`` calibrates the simulated rig at T: it calibrated at the
plans' default 0.01 s whatever the scan's exposure, so a scan at 0.05 s came out 5 times too
bright (counts are not rescaled between exposures), 'outside physical bounds', with the
result's calibration_warning the only word of why. The same data directory scanned again at
another exposure is calibrated again at that one."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from gonio.brdf.tables.geometry import lab_to_specimen
from gonio.cli import main
from gonio.results import read_result
from gonio.sim.rig import default_material

pytestmark = pytest.mark.timeout(900)


def _median_rel_error(path: Path) -> float:
    s = read_result(path).samples
    alpha = np.deg2rad(s.stage_angles_deg)[None, :]
    wi = lab_to_specimen(np.asarray(s.light_dirs)[:, None, :], alpha)
    wo = lab_to_specimen(np.asarray(s.sensor_dirs)[:, None, :], alpha)
    truth = default_material().eval(wi.reshape(-1, 3), wo.reshape(-1, 3)).reshape(s.values.shape)
    rel = np.abs(s.values - truth) / np.maximum(truth, 0.05 * truth.max())
    return float(np.median(rel))


def test_a_sim_scan_is_calibrated_at_its_own_exposure(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    data = tmp_path / "data"
    for k, exposure in enumerate(("0.05", "0.02")):
        out = tmp_path / f"scan{k}.h5"
        assert main(["scan", "--no-export-fits", "--sim", "--rotations", "2",
                     "--time-scale", "10", "--no-progress", "--exposure", exposure,
                     "--data-dir", str(data), "-o", str(out)]) == 0
        err = capsys.readouterr().err
        assert "calibrating the simulated rig" in err, err
        assert "warning: exposure:" not in err, err
        res = read_result(out)
        assert res.samples.calibration["exposure_s"] == pytest.approx(float(exposure))
        assert "calibration_warning" not in res.metrics, res.metrics["calibration_warning"]
        assert _median_rel_error(out) < 0.05
