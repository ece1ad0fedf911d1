"""``gonio scan`` says when a scan would be uncalibrated, refuses one on a rig that was
calibrated unless accepted, and names a wrong ``--calibration`` file (issue 27, items 1, 7).

Nothing here measures: the checks run before the rig is touched, so the example rig config
(whose devices do not exist on this machine) serves.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest

from gonio.calibration import CALIBRATION_FILE, Calibration, PairCalibration, save_calibration
from gonio.cli import main
from gonio.config import load_rig_config
from gonio.paths import scan_data_dir

RIG = Path("deploy/rig.example.toml")


@pytest.fixture
def rig_calibration() -> Iterator[Path]:
    """A calibration of every pair of the example rig in its own (gonio scan's) data
    directory, as `gonio scan --rig rig.toml --white-reference 0.99` leaves it."""
    cfg = load_rig_config(RIG)
    own = scan_data_dir(cfg)
    own.mkdir(parents=True, exist_ok=True)
    path = own / CALIBRATION_FILE
    save_calibration(Calibration(
        pairs=tuple(PairCalibration(light=p.light, sensor=p.sensor, factor=(1e-5,) * 3)
                    for p in cfg.pair_list()),
        reference_albedo=0.99, source="job 1: white reference", exposure_s=0.01), path)
    try:
        yield path
    finally:
        path.unlink()


def test_dry_run_warns_only_when_no_calibration_covers_the_plan(
    rig_calibration: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["scan", "--rig", str(RIG), "--dry-run", "-o", "/dev/null"]) == 0
    assert "uncalibrated" not in capsys.readouterr().out
    assert main(["scan", "--rig", str(RIG), "--data-dir", str(tmp_path / "other"), "--dry-run",
                 "-o", "/dev/null"]) == 0
    out = capsys.readouterr().out
    assert "warning: uncalibrated: no calibration is in effect" in out, out
    assert "sensor units, not 1/sr" in out
    # ... and, on the command line, which command calibrates (it named none).
    assert f"here: with the white reference on the stage, 'gonio scan --rig {RIG} " \
           "--white-reference 0.99 -o white.h5'" in out, out


def test_an_uncalibrated_scan_of_a_calibrated_rig_is_refused_unless_accepted(
    rig_calibration: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "felt.h5"
    assert main(["scan", "--rig", str(RIG), "--data-dir", str(tmp_path / "other"),
                 "--no-progress", "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert "would be uncalibrated although the rig was calibrated" in err, err
    assert str(rig_calibration.parent) in err and "--accept-uncalibrated" in err, err
    assert not out.exists()


def test_a_toml_given_as_calibration_is_named_with_what_is_expected(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    geometry = tmp_path / "geometry.toml"
    geometry.write_text('[[lights]]\nname = "L1"\ntheta_deg = 30.0\nphi_deg = 0.0\n')
    assert main(["scan", "--rig", str(RIG), "--calibration", str(geometry), "--data-dir",
                 str(tmp_path / "d"), "--no-progress", "-o", str(tmp_path / "x.h5")]) == 2
    err = capsys.readouterr().err
    assert f"--calibration {geometry}: not a calibration file" in err, err
    assert "TOML" in err and "white.calibration.json" in err, err
    assert "value: Invalid JSON" not in err


def test_dry_run_warns_of_a_calibration_measured_at_another_exposure(
    rig_calibration: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # A calibration at 0.01 s and a scan at 0.5 s: values 50 times off, said only in the
    # result's calibration_warning after the scan (the page's headline: "Calibrated").
    assert main(["scan", "--rig", str(RIG), "--dry-run", "-o", "/dev/null"]) == 0
    assert "exposure:" not in capsys.readouterr().out
    assert main(["scan", "--rig", str(RIG), "--exposure", "0.5", "--dry-run",
                 "-o", "/dev/null"]) == 0
    out = capsys.readouterr().out
    assert ("exposure: the calibration in effect (job 1: white reference) was measured at "
            "0.01 s and this scan reads at 0.5 s") in out, out
    assert ("off by about 50 times, and such a scan is refused: scan at 0.01 s, or calibrate "
            "at 0.5 s first") in out, out


def test_dry_run_of_a_partly_calibrated_plan_says_it_would_be_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # The rig config's factors cover L1/S1 only: the dry run said the scan's values would
    # 'stay in sensor units', and gonio scan printed that warning, then refused the scan.
    rig = tmp_path / "rig.toml"
    rig.write_text(RIG.read_text() + '\n[[calibration.factors]]\nlight = "L1"\nsensor = "S1"\n'
                   'factor = [1e-5, 1e-5, 1e-5]\n')
    data = str(tmp_path / "data")
    assert main(["scan", "--rig", str(rig), "--data-dir", data, "--dry-run",
                 "-o", "/dev/null"]) == 0
    out = capsys.readouterr().out
    assert "not calibrated: the calibration in effect (rig config) has no factors for " \
           "pair(s) L1/S2" in out, out
    assert "so the scan would be refused when submitted" in out, out
    assert "sensor units" not in out, out


def test_a_scan_at_another_exposure_than_the_calibration_is_refused_before_it_measures(
    rig_calibration: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """It measured with a warning, its values 50 times off: the sensors are not assumed
    linear in exposure (gonio.calibration), so a calibration at 0.01 s cannot serve 0.5 s."""
    out = tmp_path / "felt.h5"
    assert main(["scan", "--rig", str(RIG), "--exposure", "0.5", "--no-progress",
                 "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert "reads at exposure 0.5 s" in err and "measured at 0.01 s" in err, err
    assert "calibrate at 0.5 s first" in err and "--white-reference" in err, err
    assert not out.exists()
