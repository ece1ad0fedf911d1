"""Tests of the shipped measured tables and ``gonio library import``."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from gonio.brdf.materials import measured
from gonio.brdf.materials.imports import (
    MERL_SCALE,
    TableImportError,
    import_files,
    read_any,
    read_merl_table,
)
from gonio.brdf.tables import geometry as geo
from gonio.brdf.tables.table import BRDFTable
from gonio.cli import main


@pytest.fixture()
def libdir(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    d = tmp_path / "library"
    monkeypatch.setenv("GONIO_LIBRARY_DIR", str(d))
    return d


def write_merl(path: Path, dims: tuple[int, int, int], fn) -> None:  # type: ignore[no-untyped-def]
    """A MERL .binary file from its documented layout: value = fn(th, td, pd) / scale."""
    n_th, n_td, n_pd = dims
    i_th, i_td, i_pd = np.meshgrid(np.arange(n_th), np.arange(n_td), np.arange(n_pd),
                                   indexing="ij")
    # Each stored value is a bin, sampled at its centre; th on the non-linear axis.
    th = ((i_th + 0.5) / n_th) ** 2 * (np.pi / 2)
    td = (i_td + 0.5) / n_td * (np.pi / 2)
    pd = (i_pd + 0.5) / n_pd * np.pi
    data = np.stack([fn(th, td, pd) * (c + 1) / MERL_SCALE[c] for c in range(3)])
    with open(path, "wb") as fh:
        fh.write(np.array(dims, dtype="<i4").tobytes())
        fh.write(data.astype("<f8").tobytes())


def test_shipped_measured_tables_are_isotropic_rgb_and_credited() -> None:
    tables = measured.measured_tables()
    assert len(tables) == 11 and len({t.name for t in tables}) == 11
    t = tables[0]
    assert t.values.shape == (3, *geo.TABLE_SHAPE) and t.channels == ("R", "G", "B")
    v = t.values[:, :, geo.valid_mask()]
    assert np.all(v >= 0) and np.all(v == v[:, :1])  # one slice copied to all 72
    assert "CC0" in t.provenance["credit"]
    kept = measured.measured_tables(exclude=["chm_mint"])
    assert len(kept) == 10 and "rgl-chm_mint" not in {k.name for k in kept}


def test_merl_file_is_read_at_the_documented_indices(tmp_path: Path) -> None:
    """A function linear in the index-space coordinates is reproduced exactly by the
    trilinear read, so the test checks the layout, the axes' mappings and the scales."""
    f = tmp_path / "lin.binary"
    # Linear in sqrt(th) (the th index), td and pd.
    write_merl(f, (12, 10, 20), lambda th, td, pd: 0.1 + np.sqrt(th / (np.pi / 2)) + td + 0.1 * pd)
    t = read_merl_table(f)
    th, td, pd = geo.grid_angles()
    m = geo.valid_mask()
    # Clamped at the first and last bin centres of each axis, as the reader documents.
    sq = np.clip(np.sqrt(th / (np.pi / 2)) * 12, 0.5, 11.5) / 12
    tdc = np.clip(td / (np.pi / 2) * 10, 0.5, 9.5) / 10 * (np.pi / 2)
    pdc = np.clip(pd / np.pi * 20, 0.5, 19.5) / 20 * np.pi
    want = 0.1 + sq + tdc + 0.1 * pdc
    for c in range(3):
        np.testing.assert_allclose(t.values[c, 5][m], (c + 1) * want[m], rtol=1e-5)
    assert t.provenance["source"] == "merl"


def test_merl_negative_values_are_unmeasured(tmp_path: Path) -> None:
    f = tmp_path / "holes.binary"
    # Bins with td > 60 deg unmeasured; the rest hold 0.5 (R).
    write_merl(f, (6, 6, 12), lambda th, td, pd: np.where(td > np.deg2rad(60), -1.0, 0.5))
    t = read_merl_table(f)
    _, td, _ = geo.grid_angles()
    m = geo.valid_mask()
    # Beyond the last measured bin centre (52.5 deg) only unmeasured neighbours: NaN ...
    assert np.isnan(t.values[0, 0][m & (td > np.deg2rad(67.5))]).all()
    # ... and cells between measured and unmeasured centres read the measured value alone.
    near = m & (td > np.deg2rad(55)) & (td < np.deg2rad(65))
    np.testing.assert_allclose(t.values[0, 0][near], 0.5, rtol=1e-6)
    np.testing.assert_allclose(t.values[0, 0][m & (td < np.deg2rad(40))], 0.5, rtol=1e-6)


@pytest.mark.parametrize(
    ("content", "match"),
    [(b"abc", "too short"), (np.array([90, 90, 180], "<i4").tobytes() + b"\0" * 80, "truncated"),
     (np.array([0, 5, 5], "<i4").tobytes(), "not a MERL table")],
)
def test_bad_merl_files_are_clear_errors(tmp_path: Path, content: bytes, match: str) -> None:
    f = tmp_path / "bad.binary"
    f.write_bytes(content)
    with pytest.raises(TableImportError, match=match):
        read_merl_table(f)


def test_import_round_trips_a_gonio_table(tmp_path: Path, libdir: Path,
                                          capsys: pytest.CaptureFixture[str]) -> None:
    rng = np.random.default_rng(0)
    vals = rng.uniform(0.01, 2.0, (3, *geo.TABLE_SHAPE)).astype(np.float32)
    vals[:, :, ~geo.valid_mask()] = np.nan
    src = BRDFTable(vals, ("R", "G", "B"), "my paint").save(tmp_path / "paint.npz")
    assert main(["library", "import", str(src)]) == 0
    files = measured.user_table_files()
    assert [f.name for f in files] == ["my_paint.npz"]
    back = BRDFTable.load(files[0])
    np.testing.assert_array_equal(back.values, vals)
    assert back.name == "my_paint"
    assert measured.user_tables()[0].name == "my_paint"
    # A second import of the same name needs --replace; nothing is overwritten meanwhile.
    before = files[0].read_bytes()
    capsys.readouterr()
    assert main(["library", "import", str(src)]) == 2
    assert files[0].read_bytes() == before
    assert capsys.readouterr().err.rstrip().endswith("pass --replace to overwrite it")
    with pytest.raises(TableImportError, match=r"pass replace=True to overwrite it$"):
        import_files([src])
    assert main(["library", "import", "--replace", str(src)]) == 0


def test_import_says_how_many_it_imported_and_how_many_the_library_holds(
    tmp_path: Path, libdir: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # It said "1 table(s) in DIR" after a second import into a folder holding two.
    vals = np.full((3, *geo.TABLE_SHAPE), 0.3, np.float32)
    vals[:, :, ~geo.valid_mask()] = np.nan
    for name in ("first", "second"):
        src = BRDFTable(vals, ("R", "G", "B"), name).save(tmp_path / f"{name}.npz")
        assert main(["library", "import", str(src)]) == 0
    last = capsys.readouterr().out.strip().splitlines()[-1]
    assert last.startswith(f"1 table(s) imported; 2 in {measured.user_library_dir()};"), last


def test_import_of_a_merl_file_and_the_basis_key(tmp_path: Path, libdir: Path) -> None:
    f = tmp_path / "gold.binary"
    write_merl(f, (8, 8, 16), lambda th, td, pd: 0.2 + 0.0 * th)
    before = measured.user_library_digest()
    import_files([f])
    assert (libdir / "gold.npz").is_file()
    # Every later default-basis build sees the table: its cache key changes.
    assert measured.user_library_digest() != before


def test_import_refuses_bad_files_and_writes_nothing(tmp_path: Path, libdir: Path,
                                                     capsys: pytest.CaptureFixture[str]) -> None:
    good = tmp_path / "ok.binary"
    write_merl(good, (6, 6, 12), lambda th, td, pd: 0.3 + 0.0 * th)
    bad = tmp_path / "notes.txt"
    bad.write_text("hello")
    assert main(["library", "import", str(good), str(bad)]) == 2
    assert "unknown kind of file" in capsys.readouterr().err
    # A scan's result is not refused as an "unknown kind of file" (.h5): the message gives
    # the export that makes a table of it.
    import h5py

    result = tmp_path / "felt.h5"
    with h5py.File(result, "w") as f:
        f.attrs["format"] = "gonio-result"
    assert main(["library", "import", str(good), str(result)]) == 2
    err = capsys.readouterr().err
    assert f"'gonio export {result} --format table' writes {tmp_path / 'felt.table.npz'}" \
        in err, err
    assert "unknown kind of file" not in err, err
    # A text file, or no file, named .h5 is no result: said for what it is (the export the
    # advice named then failed).
    text = tmp_path / "notes.h5"
    text.write_text("hello")
    assert main(["library", "import", str(text)]) == 2
    assert "unknown kind of file" in capsys.readouterr().err
    assert main(["library", "import", str(tmp_path / "gone.h5")]) == 2
    assert "no such file" in capsys.readouterr().err
    assert measured.user_table_files() == []
    with pytest.raises(TableImportError, match="no such file"):
        read_any(tmp_path / "missing.bsdf")
    with pytest.raises(TableImportError, match="shipped"):
        import_files([BRDFTable(np.where(geo.valid_mask(), 0.5, np.nan)[None, None].repeat(
            3, 0).repeat(72, 1).astype(np.float32), ("R", "G", "B"), "rgl-x").save(
            tmp_path / "x.npz")])


def test_rgl_import_without_mitsuba_says_how_to_get_it(tmp_path: Path, libdir: Path,
                                                       monkeypatch: pytest.MonkeyPatch,
                                                       rgl_dir: Path) -> None:
    import builtins

    real_import = builtins.__import__

    def no_mitsuba(name: str, *a, **k):  # type: ignore[no-untyped-def]
        if name == "mitsuba":
            raise ImportError("no mitsuba")
        return real_import(name, *a, **k)

    monkeypatch.setattr(builtins, "__import__", no_mitsuba)
    with pytest.raises(ValueError, match="pip install"):
        import_files([next(iter(sorted(rgl_dir.glob("*.bsdf"))))])
    assert measured.user_table_files() == []


def test_a_table_written_by_gonio_export_merl_imports_back(tmp_path: Path) -> None:
    """Cross-check with the independent MERL writer of gonio.export (full 90 x 90 x 180)."""
    merl = pytest.importorskip("gonio.export.merl")
    th, td, pd = geo.grid_angles()
    m = geo.valid_mask()
    # A smooth isotropic BRDF: the two resamplings (grid -> MERL bins -> grid) stay close.
    slice_ = np.where(m, 0.2 + 0.3 * np.cos(th) ** 2 + 0.1 * np.sin(td) * np.cos(2 * pd),
                      np.nan)
    vals = np.stack([slice_ * (c + 1) for c in range(3)])[:, None].repeat(72, 1)
    src = BRDFTable(vals.astype(np.float32), ("R", "G", "B"), "smooth")
    path = merl.write_merl(src, tmp_path / "smooth.binary")
    back = read_merl_table(path)
    inner = m & (th < np.deg2rad(60)) & (td < np.deg2rad(60))
    np.testing.assert_allclose(back.values[:, 3][:, inner], src.values[:, 3][:, inner],
                               rtol=0.02)


def test_importing_an_rgl_file_reports_how_far_from_reciprocal_it_is(
        rgl_dir: Path, libdir: Path, capsys: pytest.CaptureFixture[str]) -> None:
    pytest.importorskip("mitsuba")
    src = rgl_dir / "cm_military_green_rgb.bsdf"
    assert main(["library", "import", str(src)]) == 0
    out = capsys.readouterr().out
    rec = BRDFTable.load(measured.user_table_files()[0]).provenance["reciprocity"]
    # The recorded logarithms printed as factors, over the grid and over its steep part.
    assert (f"differ by a median factor of {np.exp(rec['median_abs_log_ratio']):.2f} over the "
            f"grid, by more than {np.exp(rec['p90_abs_log_ratio']):.2f} in 1 cell of 10") in out
    assert (f"({np.exp(rec['median_abs_log_ratio_below_80deg']):.2f} and "
            f"{np.exp(rec['p90_abs_log_ratio_below_80deg']):.2f} with light and view") in out
    assert "docs/science.md 7.0.1" in out
    # The file is one of the shipped materials: the import says it now counts twice.
    assert ("note: gonio already ships this material as 'rgl-cm_military_green' in its "
            "default basis") in out
    # A gonio table carries no such record, and the import says nothing of it.
    vals = np.where(geo.valid_mask(), 0.3, np.nan)[None, None].repeat(3, 0).repeat(72, 1)
    plain = BRDFTable(vals.astype(np.float32), ("R", "G", "B"), "plain").save(
        libdir.parent / "plain.npz")
    assert main(["library", "import", str(plain)]) == 0
    out = capsys.readouterr().out
    assert "reciprocal" not in out and "already ships" not in out


def test_importing_a_table_whose_scan_was_warned_about_says_the_warnings(
        libdir: Path, capsys: pytest.CaptureFixture[str]) -> None:
    # A table exported from a scan 50 times off (its calibration at another exposure) and
    # outside physical bounds was imported without a word; it then trains every default
    # basis and can be a later fit's local prior.
    warned = ["the calibration was measured at exposure 0.01 s, this scan at 0.5 s; its values "
              "are off by about the ratio. Calibrate at the scan's exposure",
              "the reconstruction is outside physical bounds: ... do not use this table "
              "without checking it"]
    vals = np.where(geo.valid_mask(), 0.3, np.nan)[None, None].repeat(3, 0).repeat(72, 1)
    path = BRDFTable(vals.astype(np.float32), ("R", "G", "B"), "felt-B",
                     provenance={"warnings": warned}).save(libdir.parent / "felt-B.table.npz")
    assert main(["library", "import", str(path)]) == 0
    out = capsys.readouterr().out
    assert "warning: the table's record carries 2 warning(s) from the scan it came from" in out
    assert f"delete {libdir / 'felt-B.npz'} to take it out" in out
    assert all(f"    - {w}" in out for w in warned), out


def test_the_user_library_moves_with_the_data_folder(tmp_path: Path,
                                                     monkeypatch: pytest.MonkeyPatch) -> None:
    # A lab that points GONIO_DATA_DIR at its own disk found its scans there and its imported
    # tables still in the platform's folder.
    from gonio import paths

    assert measured.DATA_ENV == paths.DATA_ENV
    monkeypatch.delenv(measured.LIBRARY_ENV, raising=False)
    monkeypatch.setenv(paths.DATA_ENV, str(tmp_path / "data"))
    assert measured.user_library_dir() == tmp_path / "data" / "library"
    assert measured.user_library_dir().parent == paths.user_data_root()
    # Its own variable still wins.
    monkeypatch.setenv(measured.LIBRARY_ENV, str(tmp_path / "lib"))
    assert measured.user_library_dir() == tmp_path / "lib"
