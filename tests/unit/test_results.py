"""Result files: round trip and clear errors for damaged files (gonio.results)."""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np
import pytest

from gonio.brdf.tables import geometry as geo
from gonio.brdf.tables.table import BRDFTable
from gonio.calibration import Calibration, calibrated_samples
from gonio.hal import PairSpec
from gonio.results import ResultFileError, read_provenance, read_result, write_result
from tests.unit.test_calibration import _reading_rows


def test_result_round_trip(tmp_path: Path) -> None:
    pairs = [PairSpec(light="L1", sensor="S1"), PairSpec(light="L1", sensor="S2")]
    dirs = np.tile([0.0, 0.0, 1.0], (2, 1))
    s = calibrated_samples(_reading_rows(), pairs, dirs, dirs, ("R", "G", "B"), Calibration())
    vals = np.full((3, *geo.TABLE_SHAPE), 0.25)
    table = BRDFTable(vals, ("R", "G", "B"), "spec")
    path = write_result(tmp_path / "r.h5", job_id=3, specimen="spec", kind="uniform",
                        readings=_reading_rows(), samples=s, table=table,
                        coefficients=np.zeros((3, 4, 72)), rel_sample_error=0.1,
                        estimated_error=0.08, settings={"K": 4}, metrics={"n_samples": 6},
                        provenance={"plan": {"kind": "uniform"}, "basis_K": 4})
    res = read_result(path)
    assert res.attrs["job_id"] == 3 and res.attrs["format"] == "gonio-result"
    assert res.readings == _reading_rows()
    assert res.samples.pairs == [("L1", "S1"), ("L1", "S2")]
    np.testing.assert_allclose(res.samples.values, s.values)
    assert res.table is not None
    np.testing.assert_allclose(np.nan_to_num(res.table.values), np.nan_to_num(table.values),
                               rtol=1e-6)
    assert res.estimated_error == pytest.approx(0.08) and res.settings == {"K": 4}
    assert res.metrics["n_samples"] == 6 and res.provenance["basis_K"] == 4
    assert not (tmp_path / "r.h5.part").exists()
    assert res.table.wavelengths_nm is None and res.colour == {}


def test_result_keeps_wavelengths_and_the_colour_group(tmp_path: Path) -> None:
    pairs = [PairSpec(light="L1", sensor="S1"), PairSpec(light="L1", sensor="S2")]
    dirs = np.tile([0.0, 0.0, 1.0], (2, 1))
    s = calibrated_samples(_reading_rows(), pairs, dirs, dirs, ("R", "G", "B"), Calibration())
    table = BRDFTable(np.full((3, *geo.TABLE_SHAPE), 0.25), ("b450", "b550", "b650"), "spec",
                      (450.0, 550.0, 650.0))
    colour = {"source": {"bands": {"centres_nm": [450, 550, 650]}}, "report": {"rows": []}}
    path = write_result(tmp_path / "r.h5", job_id=3, specimen="spec", kind="uniform",
                        readings=_reading_rows(), samples=s, table=table, colour=colour)
    res = read_result(path)
    assert res.table is not None and res.table.wavelengths_nm == (450.0, 550.0, 650.0)
    assert res.colour == colour
    import h5py

    with h5py.File(path, "a") as f:
        f["colour"].attrs["report"] = "{not json"
    assert read_result(path).colour == {}  # damaged: read as absent, the rest stays readable


def test_result_errors(tmp_path: Path) -> None:
    with pytest.raises(ResultFileError, match="does not exist"):
        read_result(tmp_path / "nope.h5")
    bad = tmp_path / "bad.h5"
    bad.write_text("not hdf5")
    with pytest.raises(ResultFileError, match="not an HDF5 file"):
        read_result(bad)


def test_reading_ranges_round_trip_and_older_files_read_as_range_0(tmp_path: Path) -> None:
    import dataclasses

    import h5py

    pairs = [PairSpec(light="L1", sensor="S1"), PairSpec(light="L1", sensor="S2")]
    dirs = np.tile([0.0, 0.0, 1.0], (2, 1))
    rows = _reading_rows()
    rows[1] = dataclasses.replace(rows[1], range_index=2, range_scale=0.01)
    s = calibrated_samples(rows, pairs, dirs, dirs, ("R", "G", "B"), Calibration())
    path = write_result(tmp_path / "r.h5", job_id=1, specimen="s", kind="uniform",
                        readings=rows, samples=s, provenance={})
    assert read_result(path).readings == rows
    # A file written before auto-ranging has neither dataset: every reading was in range 0.
    with h5py.File(path, "a") as f:
        del f["raw/range_index"], f["raw/range_scale"]
    old = read_result(path).readings
    assert all(r.range_index == 0 and r.range_scale == 1.0 for r in old)
    assert [r.raw for r in old] == [r.raw for r in rows]


def test_a_truncated_result_is_damaged_for_the_check_and_the_reader(tmp_path: Path) -> None:
    from gonio.results import check_result_file

    pairs = [PairSpec(light="L1", sensor="S1"), PairSpec(light="L1", sensor="S2")]
    dirs = np.tile([0.0, 0.0, 1.0], (2, 1))
    s = calibrated_samples(_reading_rows(), pairs, dirs, dirs, ("R", "G", "B"), Calibration())
    table = BRDFTable(np.full((3, *geo.TABLE_SHAPE), 0.25), ("R", "G", "B"), "spec")
    path = write_result(tmp_path / "r.h5", job_id=3, specimen="spec", kind="uniform",
                        readings=_reading_rows(), samples=s, table=table)
    check_result_file(path)
    whole = path.read_bytes()
    for keep in (len(whole) // 2, len(whole) - 1, 100):
        path.write_bytes(whole[:keep])
        with pytest.raises(ResultFileError, match=str(path)):
            check_result_file(path)
        with pytest.raises(ResultFileError, match=str(path)):
            read_result(path)
    path.unlink()
    with pytest.raises(ResultFileError, match="does not exist"):
        check_result_file(path)


def test_the_provenance_of_any_result_version_reads_alone_or_says_why_not(tmp_path: Path
                                                                         ) -> None:
    # Written by hand as docs/engine.md lays it out, at a format version this gonio does not
    # read whole: its provenance still reads (what a rebuild takes from an older result).
    older = tmp_path / "older.h5"
    with h5py.File(older, "w") as f:
        f.attrs.update(format="gonio-result", version=0)
        f.create_group("provenance").attrs.update(rig_config='{"rig": {"name": "r"}}',
                                                  plan="{}")
    assert read_provenance(older) == {"rig_config": '{"rig": {"name": "r"}}', "plan": "{}"}
    with pytest.raises(ResultFileError, match="does not exist"):
        read_provenance(tmp_path / "none.h5")
    other = tmp_path / "other.h5"
    with h5py.File(other, "w") as f:
        f.attrs["format"] = "something-else"
    with pytest.raises(ResultFileError, match="not a gonio result file"):
        read_provenance(other)
    bare = tmp_path / "bare.h5"
    with h5py.File(bare, "w") as f:
        f.attrs["format"] = "gonio-result"
    with pytest.raises(ResultFileError, match="has no /provenance group"):
        read_provenance(bare)
    junk = tmp_path / "junk.h5"
    junk.write_bytes(b"not hdf5 at all" * 10)
    with pytest.raises(ResultFileError, match="damaged"):
        read_provenance(junk)


def test_a_file_h5py_cannot_open_is_called_damaged_only_when_it_is_hdf5(tmp_path: Path) -> None:
    table = tmp_path / "felt.table"
    BRDFTable(np.full((3, *geo.TABLE_SHAPE), 0.25), ("R", "G", "B"), "spec").save(
        tmp_path / "t.npz").rename(table)
    with pytest.raises(ResultFileError, match=r"is a \.npz archive .*not a scan's result file"):
        read_result(table)
    cut = tmp_path / "cut.h5"
    with h5py.File(cut, "w") as f:
        f.attrs["format"] = "gonio-result"
        f.create_dataset("x", data=np.zeros(1000))
    cut.write_bytes(cut.read_bytes()[:600])
    with pytest.raises(ResultFileError, match="is an HDF5 file but damaged"):
        read_result(cut)
