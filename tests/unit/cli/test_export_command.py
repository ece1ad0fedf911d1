"""'gonio export' on result files: every format, stored fits, provenance, bad input."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from gonio.brdf.materials import library
from gonio.brdf.models import analytic as bm
from gonio.brdf.models.factored import FactoredBRDF
from gonio.calibration import CalibratedScan
from gonio.cli import main
from gonio.results import read_result, write_result
from tests.unit.export.test_metadata import library_principled, stand_in_fits


def _samples() -> CalibratedScan:
    return CalibratedScan(pairs=[("L1", "S1")], light_dirs=np.array([[0.0, 0.0, 1.0]]),
                   sensor_dirs=np.array([[0.0, 0.0, 1.0]]), stage_angles_deg=np.array([0.0]),
                   values=np.ones((1, 1, 3)), channels=("R", "G", "B"))


@pytest.fixture(scope="module")
def result(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A result file of a library brushed metal with its fits stored, as the daemon writes,
    the principled one the metal's own parameters recorded as a rendered fit
    (:func:`tests.unit.export.test_metadata.stand_in_fits`: what is tested here is storing
    and exporting; the export's own principled fit of this table is made, and checked
    against the metal's parameters, by the refit test below)."""
    table = bm.tabulate(library.get_material("brushed-metal-003"))
    fits = stand_in_fits(table, library_principled("brushed-metal-003"))
    return write_result(
        tmp_path_factory.mktemp("res") / "job-5.h5", job_id=5, specimen="brushed",
        kind="uniform", readings=[], samples=_samples(), table=table,
        metrics={"predicted_error": 0.03}, factored=fits.factored, principled=fits.principled,
    )


def test_fits_are_stored_in_the_result(result: Path) -> None:
    res = read_result(result)
    assert res.factored is not None and res.principled is not None
    assert res.factored.D.shape == (18, 72) and res.factored.metrics["rel_mse"] > 0
    assert res.principled.roughness == pytest.approx(
        (0.10277148177302968 * 0.37092948532791287) ** 0.25, rel=0.1)
    assert res.principled.metrics["fit"] == "rendered"
    assert 0 <= res.principled.metrics["rendered"]["value"] < 1


@pytest.mark.parametrize("fmt", ["factored", "mtlx", "gltf", "glb", "merl", "table"])
def test_every_format(result: Path, tmp_path: Path, fmt: str,
                      capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / f"x.{fmt}"
    assert main(["export", str(result), "--format", fmt, "-o", str(out)]) == 0
    assert "wrote" in capsys.readouterr().out and out.stat().st_size > 0
    if fmt == "factored":
        f = FactoredBRDF.load(out)
        with np.load(out) as z:
            prov = json.loads(str(z["provenance"]))
        assert f.D.shape == (18, 72) and prov["job_id"] == 5 and prov["specimen"] == "brushed"
    elif fmt == "gltf":
        assert json.loads(out.read_text())["asset"]["extras"]["job_id"] == 5
    elif fmt == "glb":
        # glTF 2.0's binary container: magic "glTF", version 2, then the JSON chunk
        data = out.read_bytes()
        assert data[:4] == b"glTF" and int.from_bytes(data[4:8], "little") == 2
        size = int.from_bytes(data[12:16], "little")
        assert data[16:20] == b"JSON"
        assert json.loads(data[20:20 + size])["asset"]["extras"]["job_id"] == 5
    elif fmt == "mtlx":
        assert "&quot;job_id&quot;: 5" in out.read_text()
    elif fmt == "table":
        from gonio.brdf.tables.table import BRDFTable

        assert BRDFTable.load(out).provenance["job_id"] == 5
    else:
        from gonio.brdf.materials.merl import read_merl_values

        assert read_merl_values(out).shape == (3, 90, 90, 180)


def test_bad_input(result: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["export", str(tmp_path / "none.h5"), "-f", "gltf"]) == 2
    assert "does not exist" in capsys.readouterr().err
    assert main(["export", str(result), "-f", "gltf", "-o", str(tmp_path / "no/dir/x")]) == 2
    assert "does not exist" in capsys.readouterr().err
    assert main(["export", str(result), "-f", "table", "-o", str(result)]) == 2
    assert "result file itself" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["export", str(result), "-f", "obj"])
    calib = write_result(tmp_path / "cal.h5", job_id=6, specimen="white", kind="calibration",
                         readings=[], samples=_samples())
    assert main(["export", str(calib), "-f", "gltf", "-o", str(tmp_path / "c.gltf")]) == 2
    assert "without a reconstructed BRDF" in capsys.readouterr().err
    before = calib.read_bytes()
    assert calib.read_bytes() == before  # nothing stored was touched
    not_h5 = tmp_path / "n.h5"
    not_h5.write_text("hello")
    assert main(["export", str(not_h5), "-f", "gltf", "-o", str(tmp_path / "n.gltf")]) == 2
    assert "not an HDF5 file" in capsys.readouterr().err


def test_default_names_do_not_collide(result: Path, tmp_path: Path,
                                      capsys: pytest.CaptureFixture[str]) -> None:
    """Without -o every format gets its own file: factored and table are both .npz."""
    res = tmp_path / result.name
    res.write_bytes(result.read_bytes())
    for fmt in ("factored", "table", "gltf"):
        assert main(["export", str(res), "--format", fmt]) == 0
    names = sorted(p.name for p in tmp_path.iterdir())
    assert names == ["job-5.factored.npz", "job-5.gltf", "job-5.h5", "job-5.table.npz"]
    FactoredBRDF.load(tmp_path / "job-5.factored.npz")  # not overwritten by the table
    from gonio.brdf.tables.table import BRDFTable

    assert BRDFTable.load(tmp_path / "job-5.table.npz").provenance["job_id"] == 5


@pytest.mark.parametrize("fmt", ["merl", "mtlx", "gltf"])
def test_a_table_that_is_not_rgb_gives_an_export_error(tmp_path: Path, fmt: str) -> None:
    """The daemon maps ExportError to a 404 with the reason; other errors would be a 500."""
    from gonio.brdf.models.principled import Principled
    from gonio.brdf.tables.table import BRDFTable
    from gonio.export import ExportError, Fits, write_export

    rgb = bm.tabulate(library.get_material("brushed-metal-003"))
    grey = BRDFTable.trusted(rgb.values[:1].copy(), ("Y",), "grey")
    factored = FactoredBRDF(np.array([0.2]), np.array([1.0]), np.ones((18, 72)),
                            np.ones((1, 18)), np.ones((19, 72)), ("Y",), "grey")
    principled = Principled((0.5,), 0.0, 0.5, 0.2, 0.1, 30.0, ("Y",))
    out = tmp_path / f"grey.{fmt}"
    with pytest.raises(ExportError, match=r"three channels.*'table' and 'factored'"):
        write_export(Fits(grey, factored, principled), fmt, out, {})
    assert not out.exists() and list(tmp_path.iterdir()) == []  # no partial file left


def test_merl_holds_the_srgb_table_of_a_result_with_colour(tmp_path: Path) -> None:
    """A chart-calibrated RGB sensor's raw channels are not sRGB: MERL was written from them
    while its sidecar's colour_space said linear sRGB. It now holds the table the fits were
    made of, and a result without colour keeps its own."""
    from gonio.brdf.materials.imports import read_merl_table
    from gonio.brdf.models.principled import Principled
    from gonio.brdf.tables.table import BRDFTable, from_function
    from gonio.export import Fits, write_export

    # Diffuse tables (MERL averages over the half vector's azimuth: a diffuse table keeps its
    # values exactly), the raw channels' and another, as a conversion would give.
    def diffuse(rgb: list[float], name: str) -> BRDFTable:
        return from_function(lambda i, o: np.tile(rgb, (i.shape[0], 1)), ["R", "G", "B"], name)

    raw, srgb = diffuse([0.1, 0.2, 0.05], "raw"), diffuse([0.05, 0.3, 0.02], "srgb")
    factored = FactoredBRDF(np.full(3, 0.2), np.ones(3), np.ones((18, 72)), np.ones((3, 18)),
                            np.ones((19, 72)), ("R", "G", "B"), "x")
    principled = Principled((0.5, 0.5, 0.5), 0.0, 0.5, 0.2, 0.1, 30.0, ("R", "G", "B"))
    wi = np.array([[0.5, 0.0, np.sqrt(0.75)]])
    wo = np.array([[0.0, 0.5, np.sqrt(0.75)]])
    for table, expected in ((srgb, srgb), (None, raw)):
        out = write_export(Fits(raw, factored, principled, table), "merl",
                           tmp_path / f"{expected.name}.binary", {})
        got = read_merl_table(out).eval(wi, wo)[0]
        assert got == pytest.approx(expected.eval(wi, wo)[0], rel=1e-3), expected.name


@pytest.mark.parametrize("fmt", ["gltf", "mtlx", "factored", "table"])
def test_two_writers_of_one_path_do_not_collide(result: Path, tmp_path: Path,
                                                monkeypatch: pytest.MonkeyPatch, fmt: str) -> None:
    """The daemon may export one job twice at once (a double click): a second complete write
    running while the first is about to rename its temporary file must not break the first."""
    import os

    from gonio.export import result_fits, write_export

    fits, prov = result_fits(result)
    out = tmp_path / f"x.{fmt}"
    real_replace = os.replace
    nested = {"done": False}

    def replace_after_a_second_writer(src: object, dst: object) -> None:
        if not nested["done"]:
            nested["done"] = True
            write_export(fits, fmt, out, prov)  # the other request, start to finish
        real_replace(src, dst)  # type: ignore[arg-type]

    monkeypatch.setattr(os, "replace", replace_after_a_second_writer)
    write_export(fits, fmt, out, prov)
    assert nested["done"] and out.stat().st_size > 0
    assert sorted(p.name for p in tmp_path.iterdir()) == [out.name]  # no .part left over


def test_a_damaged_stored_fit_is_fitted_again(result: Path, tmp_path: Path,
                                              caplog: pytest.LogCaptureFixture) -> None:
    """A result whose /principled group lost its parameters still exports (refitted from the
    reconstruction), with a warning, instead of a KeyError traceback."""
    import h5py

    broken = tmp_path / "broken.h5"
    broken.write_bytes(result.read_bytes())
    with h5py.File(broken, "a") as f:
        del f["principled"]
        f.create_group("principled")  # no "params" attribute
    with caplog.at_level("WARNING", logger="gonio.results"):
        res = read_result(broken)
    assert res.principled is None and res.factored is not None and res.table is not None
    assert "/principled is damaged" in caplog.text
    out = tmp_path / "b.gltf"
    assert main(["export", str(broken), "-f", "gltf", "-o", str(out)]) == 0
    material = json.loads(out.read_text())["materials"][0]
    # Refitted (the export's rendered fit, as fit_all makes it): the library material's
    # smoother axis, alpha 0.1028 (its definition; the stored stand-in fit has it too).
    alpha_b = material["pbrMetallicRoughness"]["roughnessFactor"] ** 2
    stored = read_result(result).principled
    assert stored is not None and stored.alpha_b == pytest.approx(0.10277148177302968)
    assert alpha_b == pytest.approx(0.10277148177302968, rel=0.05)


def test_gltf_with_mesh_and_the_report(result: Path, tmp_path: Path,
                                       capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "m.gltf"
    assert main(["export", str(result), "-f", "gltf", "--with-mesh", "-o", str(out)]) == 0
    doc = json.loads(out.read_text())
    assert doc["scenes"][0]["nodes"] == [0] and "TANGENT" in (
        doc["meshes"][0]["primitives"][0]["attributes"])
    text = capsys.readouterr().out
    assert "specimen brushed, measured, job 5" in text
    assert "principled fit renders" in text and "from the reconstruction" in text
    assert "no mesh" not in text
    # Without the sphere the file has no mesh at all, and a viewer shows an empty scene: the
    # report says so and how to get one.
    bare = tmp_path / "bare.gltf"
    assert main(["export", str(result), "-f", "gltf", "-o", str(bare)]) == 0
    assert "meshes" not in json.loads(bare.read_text())
    said = capsys.readouterr().out
    assert "no mesh" in said and "--with-mesh adds a preview sphere" in said
    assert main(["export", str(result), "-f", "merl", "--with-mesh",
                 "-o", str(tmp_path / "m.binary")]) == 2
    assert "--with-mesh applies to --format gltf or glb only" in capsys.readouterr().err
    assert not (tmp_path / "m.binary").exists()


def test_glb_with_mesh_and_without(result: Path, tmp_path: Path,
                                   capsys: pytest.CaptureFixture[str]) -> None:
    """`-f glb --with-mesh` writes the binary container with its BIN chunk (the sphere);
    without the mesh the report says, as for the .gltf, that a viewer shows an empty scene."""
    out = tmp_path / "m.glb"
    assert main(["export", str(result), "-f", "glb", "--with-mesh", "-o", str(out)]) == 0
    data = out.read_bytes()
    assert data[:4] == b"glTF" and int.from_bytes(data[8:12], "little") == len(data)
    size = int.from_bytes(data[12:16], "little")
    assert data[20 + size + 4:20 + size + 8] == b"BIN\x00"
    assert "no mesh" not in capsys.readouterr().out
    bare = tmp_path / "bare.glb"
    assert main(["export", str(result), "-f", "glb", "-o", str(bare)]) == 0
    assert len(bare.read_bytes()) == 20 + int.from_bytes(bare.read_bytes()[12:16], "little")
    said = capsys.readouterr().out
    assert "no mesh" in said and "--with-mesh adds a preview sphere" in said


@pytest.mark.parametrize(("fmt", "name", "other"), [("gltf", "felt.glb", "glb"),
                                                    ("glb", "felt.gltf", "gltf")])
def test_gltf_and_glb_suffixes_are_not_mixed(
    result: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], fmt: str, name: str,
    other: str,
) -> None:
    """`-f gltf -o felt.glb` wrote glTF JSON into a .glb, which viewers that open a .glb by
    its binary header (three.js, Blender, model-viewer) refuse: refused, with the right name
    and the format that name asks for, before anything is written (and the other way)."""
    assert main(["export", str(result), "-f", fmt, "-o", str(tmp_path / name)]) == 2
    err = capsys.readouterr().err
    assert f"has the suffix of the {other} format, but --format is {fmt}" in err, err
    assert f"name it felt.{fmt}" in err and f"--format {other}" in err, err
    assert "nothing was written" in err
    assert list(tmp_path.iterdir()) == []


def test_a_table_file_is_told_apart_from_a_result(tmp_path: Path,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    """A newcomer gave `gonio export` the gonio table (.npz) the page had exported, to turn it
    into glTF, and read "is not an HDF5 file or is damaged": it is neither damaged nor a
    result, and the message now says what it is and what export reads."""
    table = bm.tabulate(library.library_specs()[0].model)
    path = tmp_path / "gonio-job-2-table.npz"
    table.save(path)
    assert main(["export", str(path), "-f", "gltf", "-o", str(tmp_path / "t.gltf")]) == 2
    err = capsys.readouterr().err
    assert "not an HDF5 file" not in err and "damaged" not in err, err
    assert "gonio-job-2-table.npz is a .npz archive (a gonio table or samples file)" in err, err
    assert "result file" in err and not (tmp_path / "t.gltf").exists()


def test_a_damaged_result_file_says_what_to_do(result: Path, tmp_path: Path,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    """A result cut short (a copy, a full disk) was reported as "damaged" with nothing to do;
    the daemon's answer for the same file names the rebuild. Now the command line says to
    copy it again or rebuild it from the stored readings."""
    cut = tmp_path / "cut.h5"
    cut.write_bytes(result.read_bytes()[:4096])
    assert main(["export", str(cut), "-f", "gltf", "-o", str(tmp_path / "t.gltf")]) == 2
    err = capsys.readouterr().err
    assert "cut.h5 is an HDF5 file but damaged" in err, err
    assert "copy it again" in err and "gonio jobs rebuild N --db DATA_DIR" in err, err
    assert not (tmp_path / "t.gltf").exists()
    # The same words from reconstruct and colour, which read the file their own ways.
    for argv in (["reconstruct", str(cut), "-o", str(tmp_path / "r.npz")],
                 ["colour", str(cut)]):
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert "is an HDF5 file but damaged" in err and "copy it again" in err, (argv, err)
    # Damaged in its body (a block of zeros where the table's data was): it opens, and its
    # table cannot be read. The same words and advice.
    body = tmp_path / "body.h5"
    data = bytearray(result.read_bytes())
    data[len(data) // 2: len(data) // 2 + 65536] = bytes(65536)
    body.write_bytes(bytes(data))
    assert main(["export", str(body), "-f", "mtlx", "-o", str(tmp_path / "b.mtlx")]) == 2
    err = capsys.readouterr().err
    assert "body.h5 is an HDF5 file but damaged" in err and "copy it again" in err, err


@pytest.mark.parametrize(("lost", "words"), [
    (0.0001, "(little lost: the result is nearly isotropic, log RMSE 0.000 to its average)"),
    (0.017, "(anisotropy lost: log RMSE 0.017)"),
])
def test_the_merl_report_says_anisotropy_was_lost_only_when_it_was(
    tmp_path: Path, lost: float, words: str
) -> None:
    """An isotropic paint's MERL export read "anisotropy lost: log RMSE 0.000"."""
    import json

    from gonio.cli.export_command import report
    from gonio.export.merl import sidecar_path

    path = tmp_path / "paint.binary"
    path.write_bytes(b"")
    sidecar_path(path).write_text(json.dumps({"merl": {"anisotropy_lost": lost}}))
    lines = report("merl", path, {"specimen": "paint", "specimen_named": True,
                                  "source": "simulated", "job_id": 1})
    assert any(words in line for line in lines), lines


def test_an_existing_output_is_kept_unless_overwrite_says_to_replace_it(
    result: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """`gonio export -o` naming another scan's result replaced it with a glTF file without a
    word; a merl export's sidecar counts too."""
    other = tmp_path / "other-scan.h5"
    other.write_bytes(b"another scan's result")
    assert main(["export", str(result), "-f", "gltf", "-o", str(other)]) == 2
    err = capsys.readouterr().err
    assert f"{other} already exists" in err and "--overwrite" in err, err
    assert other.read_bytes() == b"another scan's result"
    merl = tmp_path / "felt.binary"
    (tmp_path / "felt.binary.json").write_text("{}")
    assert main(["export", str(result), "-f", "merl", "-o", str(merl)]) == 2
    assert f"{tmp_path / 'felt.binary.json'} already exists" in capsys.readouterr().err
    assert not merl.exists()
    assert main(["export", str(result), "-f", "gltf", "-o", str(other), "--overwrite"]) == 0
    assert other.read_bytes()[:1] == b"{"  # the glTF JSON


def test_an_output_that_is_a_folder_is_refused_saying_so(
    result: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """`-o FOLDER` was refused as "already exists ... add --overwrite", and with --overwrite
    failed after the fit naming a temporary "FOLDER.305855233730.part: Is a directory"."""
    folder = tmp_path / "exports"
    folder.mkdir()
    for extra in ([], ["--overwrite"]):
        assert main(["export", str(result), "-f", "gltf", "-o", str(folder), *extra]) == 2
        err = capsys.readouterr().err
        assert f"{folder} is a folder" in err and ".part" not in err, err
    assert list(folder.iterdir()) == [] and sorted(p.name for p in tmp_path.iterdir()) == [
        "exports"]


@pytest.mark.parametrize(("fmt", "name"), [("gltf", "felt.mtlx"), ("merl", "felt.gltf"),
                                           ("mtlx", "felt.binary"), ("table", "felt.gltf")])
def test_an_output_with_another_formats_suffix_is_refused(
    result: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], fmt: str, name: str
) -> None:
    """`-f gltf -o felt.mtlx` wrote glTF JSON into a file named .mtlx without a word, which a
    MaterialX reader then fails on; the suffixes are those of docs/file-formats.md."""
    want = {"gltf": ".gltf", "merl": ".binary", "mtlx": ".mtlx", "table": ".npz"}[fmt]
    assert main(["export", str(result), "-f", fmt, "-o", str(tmp_path / name)]) == 2
    err = capsys.readouterr().err
    assert name in err and want in err, err
    assert list(tmp_path.iterdir()) == []


def test_an_output_of_another_suffix_or_none_is_written(
    result: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Only the suffix of another gonio format is refused: a name of the lab's own is kept."""
    for name in ("felt", "felt.json"):
        assert main(["export", str(result), "-f", "gltf", "-o", str(tmp_path / name)]) == 0
        assert json.loads((tmp_path / name).read_text())["asset"]["version"] == "2.0"
    capsys.readouterr()
