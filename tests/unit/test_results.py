"""Result file round trip, calibration maths, and the CLI's user errors."""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np
import pytest

from gonio.brdf.tables import geometry as geo
from gonio.brdf.tables.table import BRDFTable
from gonio.calibration import (
    Calibration,
    CalibrationError,
    calibrated_samples,
    from_reference,
)
from gonio.cli import UsageError, scan_commands
from gonio.hal import PairSpec
from gonio.results import ResultFileError, read_result, write_result
from gonio.store import JobStore, ReadingRow


def _readings() -> list[ReadingRow]:
    out = []
    for k, ang in enumerate((0.0, 120.0, 240.0)):
        for s in ("S1", "S2"):
            out.append(ReadingRow(k, ang + 360.0, ang + 360.01, "L1", s, (10.0 + k, 20.0, 30.0),
                                  (1.0, 1.0, 1.0), 0.01, 2, False, 1.0))
    return out


def test_white_reference_factor() -> None:
    cal = from_reference(0.8, {("L1", "S1"): np.array([[2.0, 4.0], [2.0, 4.0]])})
    assert cal.factor("L1", "S1", 2) == pytest.approx([0.4 / math.pi, 0.2 / math.pi])
    assert cal.factor("L9", "S1", 2) == pytest.approx([1.0, 1.0])
    with pytest.raises(CalibrationError, match="every channel must be positive"):
        from_reference(0.8, {("L1", "S1"): np.array([[0.0, 4.0]])})
    with pytest.raises(CalibrationError, match="has 2 channels"):
        cal.factor("L1", "S1", 3)


def test_samples_arrangement_and_incomplete_jobs() -> None:
    pairs = [PairSpec(light="L1", sensor="S1"), PairSpec(light="L1", sensor="S2")]
    z = np.zeros((2, 3))
    s = calibrated_samples(_readings(), pairs, z, z, ("R", "G", "B"), Calibration())
    assert s.values.shape == (2, 3, 3)
    assert s.stage_angles_deg.tolist() == [0.0, 120.0, 240.0]  # modulo 360
    assert s.values[0, 1, 0] == pytest.approx(10.0)  # 11 - 1 at the second angle
    with pytest.raises(CalibrationError, match="no reading at stage angle 240"):
        calibrated_samples(_readings()[:-1], pairs, z, z, ("R", "G", "B"), Calibration())


def test_result_round_trip(tmp_path: Path) -> None:
    pairs = [PairSpec(light="L1", sensor="S1"), PairSpec(light="L1", sensor="S2")]
    dirs = np.tile([0.0, 0.0, 1.0], (2, 1))
    s = calibrated_samples(_readings(), pairs, dirs, dirs, ("R", "G", "B"), Calibration())
    vals = np.full((3, *geo.TABLE_SHAPE), 0.25)
    table = BRDFTable(vals, ("R", "G", "B"), "spec")
    path = write_result(tmp_path / "r.h5", job_id=3, specimen="spec", kind="uniform",
                        readings=_readings(), samples=s, table=table,
                        coefficients=np.zeros((3, 4, 72)), rel_sample_error=0.1,
                        estimated_error=0.08, settings={"K": 4}, metrics={"n_samples": 6},
                        provenance={"plan": {"kind": "uniform"}, "basis_K": 4})
    res = read_result(path)
    assert res.attrs["job_id"] == 3 and res.attrs["format"] == "gonio-result"
    assert res.readings == _readings()
    assert res.samples.pairs == [("L1", "S1"), ("L1", "S2")]
    np.testing.assert_allclose(res.samples.values, s.values)
    assert res.table is not None
    np.testing.assert_allclose(np.nan_to_num(res.table.values), np.nan_to_num(table.values),
                               rtol=1e-6)
    assert res.estimated_error == pytest.approx(0.08) and res.settings == {"K": 4}
    assert res.metrics["n_samples"] == 6 and res.provenance["basis_K"] == 4
    assert not (tmp_path / "r.h5.part").exists()


def test_result_errors(tmp_path: Path) -> None:
    with pytest.raises(ResultFileError, match="does not exist"):
        read_result(tmp_path / "nope.h5")
    bad = tmp_path / "bad.h5"
    bad.write_text("not hdf5")
    with pytest.raises(ResultFileError, match="not an HDF5 file"):
        read_result(bad)


def _parse(argv: list[str]) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="gonio")
    scan_commands.register(parser.add_subparsers(dest="command"))
    return parser.parse_args(argv)


def test_cli_user_errors(tmp_path: Path) -> None:
    args = _parse(["scan", "--rig", str(tmp_path / "missing.toml"), "-o", str(tmp_path / "o.h5")])
    with pytest.raises(UsageError, match="does not exist"):
        args.func(args)
    with pytest.raises(SystemExit):  # argparse: "--exposure: expected a finite number > 0"
        _parse(["scan", "--sim", "--exposure", "0", "-o", str(tmp_path / "o.h5")])
    args = _parse(["jobs", "--db", str(tmp_path / "none.sqlite")])
    with pytest.raises(UsageError, match=r"job store .* does not exist"):
        args.func(args)
    JobStore(tmp_path / "j.sqlite").create_job(kind="uniform", specimen="x", plan={}, rig={})
    args = _parse(["jobs", "show", "--db", str(tmp_path / "j.sqlite")])
    with pytest.raises(UsageError, match="needs a job id"):
        args.func(args)
    args = _parse(["jobs", "show", "9", "--db", str(tmp_path / "j.sqlite")])
    with pytest.raises(UsageError, match="no job with id 9"):
        args.func(args)


def test_cli_jobs_list(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    JobStore(tmp_path / "j.sqlite").create_job(kind="uniform", specimen="felt", plan={}, rig={})
    args = _parse(["jobs", "list", "--db", str(tmp_path / "j.sqlite")])
    assert args.func(args) == 0
    out = capsys.readouterr().out
    assert "queued" in out and "felt" in out
