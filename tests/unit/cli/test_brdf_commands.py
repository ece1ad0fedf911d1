"""Tests of the science commands: basis build, simulate-scan, reconstruct, demo."""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from gonio.brdf.reconstruction.basis import Basis
from gonio.brdf.reconstruction.samples import Samples
from gonio.brdf.tables import geometry as geo
from gonio.brdf.tables.table import BRDFTable
from gonio.cli import UsageError, main
from gonio.cli.brdf_commands import read_pairs, simple_pairs
from tests.unit.brdf.reconstruction.test_basis import small_basis, small_library

LAB_ROWS = [(45, 0, 45, 180), (45, 0, 20, 180), (30, 90, 60, 200), (15, 10, 50, 300),
            (60, 0, 30, 0), (20, 45, 70, 100), (50, 270, 10, 60), (35, 135, 35, 315)]


@pytest.fixture()
def files(tmp_path: Path) -> dict[str, Path]:
    basis = small_basis().save(tmp_path / "basis.npz")
    table = small_library()[0].save(tmp_path / "ward.npz")
    csv_path = tmp_path / "pairs.csv"
    csv_path.write_text(
        "theta_i,phi_i,theta_v,phi_v\n" + "\n".join(",".join(map(str, r)) for r in LAB_ROWS)
    )
    return {"basis": basis, "table": table, "csv": csv_path, "dir": tmp_path}


def test_read_pairs_three_spellings_agree(files: dict[str, Path]) -> None:
    d = files["dir"]
    keys = ("theta_i", "phi_i", "theta_v", "phi_v")
    (d / "p.json").write_text(json.dumps({"pairs": [dict(zip(keys, r, strict=True))
                                                    for r in LAB_ROWS]}))
    (d / "p.toml").write_text("".join(
        "[[pairs]]\n" + "".join(f"{k} = {v}\n" for k, v in zip(keys, r, strict=True))
        for r in LAB_ROWS
    ))
    cells, ph = read_pairs(files["csv"])
    for other in ("p.json", "p.toml"):
        c2, p2 = read_pairs(d / other)
        np.testing.assert_allclose(c2, cells)
        np.testing.assert_allclose(p2, ph)
    # The specular pair (45, 0) -> (45, 180) has th = 0 and td = 45 deg.
    assert cells[0, 0] == pytest.approx(0.0, abs=1e-9)
    assert cells[0, 1] == pytest.approx(np.deg2rad(45.0))


def test_read_pairs_as_cells(tmp_path: Path) -> None:
    p = tmp_path / "cells.csv"
    p.write_text("th,td,pd,ph\n10,20,30,40\n0,45,90,0\n")
    cells, ph = read_pairs(p)
    np.testing.assert_allclose(cells, np.deg2rad([[10, 20, 30], [0, 45, 90]]))
    np.testing.assert_allclose(ph, np.deg2rad([40, 0]))


@pytest.mark.parametrize(
    ("name", "text", "match"),
    [
        ("p.csv", "a,b\n1,2\n", "give either"),
        ("p.csv", "theta_i,phi_i,theta_v,phi_v\n95,0,30,0\n", r"\[0, 90\)"),
        ("p.csv", "theta_i,phi_i,theta_v,phi_v\nx,0,30,0\n", "numeric"),
        ("p.csv", "theta_i,phi_i,theta_v,phi_v\n", "no pairs"),
        ("p.json", "{not json", "cannot be parsed"),
        ("p.json", '{"pairs": 3}', "expected a list"),
        ("p.toml", "pairs = [", r"p\.toml: not valid TOML"),
        ("p.yaml", "pairs: []", "unknown type"),
    ],
)
def test_bad_pairs_files(tmp_path: Path, name: str, text: str, match: str) -> None:
    p = tmp_path / name
    p.write_text(text)
    with pytest.raises(UsageError, match=match):
        read_pairs(p)


def _spy_reconstructions(monkeypatch: pytest.MonkeyPatch) -> list[Any]:
    """Record every Reconstruction the commands make (the real function runs), so a test reads
    the misfit flag from the reconstruction rather than from the text it checks."""
    from gonio.brdf.reconstruction import reconstruct as module

    made: list[Any] = []
    real = module.reconstruct

    def spy(*args: Any, **kwargs: Any) -> Any:
        made.append(real(*args, **kwargs))
        return made[-1]

    monkeypatch.setattr(module, "reconstruct", spy)
    return made


def _check_upper_end(text: str, rec: Any, digits: int) -> None:
    """The printed upper end is 3.33 times the printed estimate, 1.83 when the reconstruction
    flags a basis misfit (docs/science.md 7.1.1), and the warning is printed exactly then."""
    found = [re.search(rf"{what} (\d+\.\d+)", text)
             for what in ("predicted log_rmse", "upper end of its interval")]
    assert all(m is not None for m in found), text
    predicted, upper = (float(m.group(1)) for m in found if m is not None)
    flagged = rec.misfit is not None and bool(rec.misfit.flagged)
    assert ("cannot hold" in text) == flagged, text
    factor = 1.83 if flagged else 3.33
    half = 0.5 * 10.0 ** -digits
    assert abs(upper - factor * predicted) <= factor * half + half


def test_simulate_then_reconstruct(
    files: dict[str, Path], capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    d = files["dir"]
    samples = d / "s.npz"
    assert main(["simulate-scan", "--table", str(files["table"]), "--pairs", str(files["csv"]),
                 "--rotations", "12", "--start", "5", "--noise", "0.02", "--seed", "3",
                 "-o", str(samples)]) == 0
    s = Samples.load(samples)
    assert s.values.shape == (len(LAB_ROWS), 12, 3)
    assert s.stage_angles[0] == pytest.approx(np.deg2rad(5.0))
    assert s.provenance["simulated_from"] == small_library()[0].name
    out = d / "rec.npz"
    png = d / "rec.png"
    made = _spy_reconstructions(monkeypatch)
    assert main(["reconstruct", str(samples), "--basis", str(files["basis"]), "-k", "8",
                 "--preview", str(png), "-o", str(out)]) == 0
    text = capsys.readouterr().out
    assert "K=8 n=8 r=12" in text and "predicted log_rmse" in text
    # Its reliability in the figures the result's own words give (it said "3 of 5").
    import re

    from gonio.export.metadata import LOG_RMSE_MEANING

    figure = re.search(r"\d+ of \d+", text)
    assert figure is not None and figure.group() in LOG_RMSE_MEANING, text
    # The upper end of the estimate's interval, both printed to 3 decimals.
    assert len(made) == 1
    _check_upper_end(text, made[0], digits=3)
    assert "half vector comes within" not in text  # LAB_ROWS' first pair is on the mirror
    t = BRDFTable.load(out)
    assert t.name == "rec" and t.values.shape == (3, *geo.TABLE_SHAPE)
    assert png.read_bytes()[:4] == b"\x89PNG"
    # Run again onto the same files: refused before any work (the table was replaced without
    # a word), kept as they were; --overwrite replaces them.
    kept = out.read_bytes()
    assert main(["reconstruct", str(samples), "--basis", str(files["basis"]), "-k", "8",
                 "--preview", str(png), "-o", str(out)]) == 2
    assert f"{out} exists: nothing was reconstructed" in capsys.readouterr().err
    assert out.read_bytes() == kept and len(made) == 1
    assert main(["reconstruct", str(samples), "--basis", str(files["basis"]), "-k", "8",
                 "--preview", str(png), "-o", str(out), "--overwrite"]) == 0
    assert len(made) == 2
    # A new table beside yesterday's preview: the refusal names the option that named it.
    assert main(["reconstruct", str(samples), "--basis", str(files["basis"]), "-k", "8",
                 "--preview", str(png), "-o", str(d / "new.npz")]) == 2
    assert "give --preview another file" in capsys.readouterr().err


def test_simulate_with_a_preset(files: dict[str, Path],
                                capsys: pytest.CaptureFixture[str]) -> None:
    pytest.importorskip("gonio.brdf.design.presets")
    out = files["dir"] / "p.npz"
    assert main(["simulate-scan", "--table", str(files["table"]), "--design-preset", "MA68",
                 "-r", "8", "-o", str(out)]) == 0
    assert Samples.load(out).values.shape[1] == 8
    capsys.readouterr()
    # Reconstructed, MA68's layout is said to stand off the mirror direction: its nearest
    # sensor is at aspecular 15 deg, a half vector tilted 7.5 deg (ASTM E2194).
    assert main(["reconstruct", str(out), "--basis", str(files["basis"]), "-k", "8",
                 "-o", str(files["dir"] / "p-rec.npz")]) == 0
    assert ("note: no pair's half vector comes within 7.5 degrees of the specimen normal "
            "(for a pair in the plane of incidence: its sensor 15 degrees off") in \
        capsys.readouterr().out


@pytest.mark.parametrize(
    ("argv", "match"),
    [
        (["reconstruct", "{dir}/missing.npz", "--basis", "{basis}", "-o", "{dir}/o.npz"],
         "no such samples file"),
        (["reconstruct", "{samples}", "--basis", "{dir}/nobasis.npz", "-o", "{dir}/o.npz"],
         "no such basis file"),
        (["reconstruct", "{samples}", "--basis", "{basis}", "-k", "99", "-o", "{dir}/o.npz"],
         "cannot keep 99"),
        (["simulate-scan", "--table", "{dir}/none.npz", "--pairs", "{csv}", "-r", "4",
          "-o", "{dir}/x.npz"], "no such table file"),
        (["simulate-scan", "--table", "{table}", "--pairs", "{dir}/none.csv", "-r", "4",
          "-o", "{dir}/x.npz"], "does not exist"),
        (["simulate-scan", "--table", "{table}", "--pairs", "{csv}", "-r", "0",
          "-o", "{dir}/x.npz"], "at least 1"),
        (["simulate-scan", "--table", "{table}", "--pairs", "{csv}", "-r", "4", "--noise", "-1",
          "-o", "{dir}/x.npz"], ">= 0"),
    ],
)
def test_user_errors_exit_2_with_a_message(
    files: dict[str, Path], argv: list[str], match: str, capsys: pytest.CaptureFixture[str]
) -> None:
    samples = files["dir"] / "s.npz"
    Samples(np.deg2rad([[10.0, 20.0, 30.0]]), np.zeros(1), np.zeros(1), np.ones((1, 1, 3)),
            ("R", "G", "B")).save(samples)
    subs = {k: str(v) for k, v in files.items()} | {"samples": str(samples)}
    assert main([a.format(**subs) for a in argv]) == 2
    err = capsys.readouterr().err
    assert "error:" in err and match in err


def test_basis_build_with_extra_tables(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    library = pytest.importorskip("gonio.brdf.materials.library")
    extra = tmp_path / "extra"
    extra.mkdir()
    small_library()[0].save(extra / "a.npz")
    synthetic = list(small_library()[1:4])

    def fake_library(extra_dirs: tuple[str, ...] = (), progress: bool = False) -> list:
        # The synthetic part is replaced by a few small tables (building the real library
        # takes minutes and is the library's own test); the extra folder is read for real.
        return synthetic + [t for d in extra_dirs for t in library.load_table_folder(d)]

    monkeypatch.setattr(library, "default_library", fake_library)
    out = tmp_path / "b.npz"
    assert main(["basis", "build", "-k", "3", "--extra", str(extra), "-o", str(out)]) == 0
    b = Basis.load(out)
    assert b.K == 3
    assert b.materials == (*(t.name for t in synthetic), small_library()[0].name)
    assert main(["basis", "build", "-k", "3", "--extra", str(extra)]) == 2
    assert "-o" in capsys.readouterr().err


def test_demo_on_a_small_library(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    library = pytest.importorskip("gonio.brdf.materials.library")
    monkeypatch.setenv("GONIO_CACHE_DIR", str(tmp_path / "cache"))
    tables = list(small_library())
    by_name = {t.name: t for t in tables}
    # A small stand-in library (the real one takes minutes to tabulate); the demo path itself
    # (leave-one-out basis, simulation, reconstruction, metrics, previews) runs for real.
    monkeypatch.setattr(library, "default_library", lambda *a, **k: list(tables))
    monkeypatch.setattr(library, "get_material", lambda name, seed=0: by_name[name])
    monkeypatch.setattr(library, "library_table", lambda name, seed=0: by_name[name])
    out = tmp_path / "demo"
    made = _spy_reconstructions(monkeypatch)
    argv = ["demo", "--material", tables[0].name, "-n", "12", "-r", "8", "-k", "8",
            "--out", str(out)]
    assert main(argv) == 0
    text = capsys.readouterr().out
    assert "log_rmse" in text and "log_psnr" in text and "self-estimated" in text
    assert len(made) == 1
    _check_upper_end(text, made[0], digits=4)  # the demo prints 4 decimals
    for f in ("reconstruction.npz", "reconstruction.png", "reference.png"):
        assert (out / f).is_file()
    cached = list((tmp_path / "cache" / "basis").glob(f"loo-{tables[0].name}-K8-*.npz"))
    assert len(cached) == 1
    assert tables[0].name not in Basis.load(cached[0]).materials


@pytest.mark.parametrize("n", [5, 10, 20, 40])
def test_simple_pairs_are_distinct_valid_cells(n: int) -> None:
    cells, ph = simple_pairs(n)
    assert cells.shape == (n, 3) and ph.shape == (n,)
    idx = np.rint(cells / geo.STEP).astype(int)
    assert len({tuple(r) for r in idx}) == n
    assert geo.valid_mask()[idx[:, 0], idx[:, 1], idx[:, 2]].all()


def test_reconstruct_says_when_the_basis_cannot_hold_the_readings(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A tilted-facet material (no twofold symmetry, no family of the shipped basis) read with
    12 grid pairs: `gonio reconstruct` prints why its estimate is a floor; a library material
    the basis holds, read the same way, prints no warning."""
    from gonio.brdf.materials import library
    from gonio.brdf.models import analytic as bm
    from gonio.brdf.reconstruction import shipped
    from tests.unit.brdf.reconstruction.test_reconstruct import grid_pairs

    b = shipped.shipped_basis(shipped.SHIPPED_COMPONENTS)
    assert b is not None
    basis = b.save(tmp_path / "shipped.npz")
    cells, ph = grid_pairs(12, seed=5)
    pairs = tmp_path / "cells.csv"
    pairs.write_text("th,td,pd,ph\n" + "\n".join(
        ",".join(f"{v:g}" for v in np.rad2deg([*c, p])) for c, p in zip(cells, ph, strict=True)))
    said = {}
    for name in ("tilted-facet-002", "plastic-005"):
        spec = next(s for s in library.library_specs(asymmetric=True) if s.name == name)
        table = bm.tabulate(spec.model, np.float32).save(tmp_path / f"{name}.npz")
        samples = tmp_path / f"{name}-s.npz"
        assert main(["simulate-scan", "--table", str(table), "--pairs", str(pairs),
                     "--rotations", "8", "--seed", "3", "-o", str(samples)]) == 0
        capsys.readouterr()
        assert main(["reconstruct", str(samples), "--basis", str(basis),
                     "-o", str(tmp_path / f"{name}-rec.npz")]) == 0
        said[name] = capsys.readouterr().out
    assert "warning: the readings carry structure the basis cannot hold" in said[
        "tilted-facet-002"]
    assert "warning" not in said["plastic-005"]


def test_reconstruct_names_the_local_prior_it_leaned_on(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """`gonio reconstruct` with a basis holding a folded-in table prints the `prior:` line
    when the fit leans on it (the specimen is that table) and not with the library prior."""
    from gonio.brdf.reconstruction.basis import fold_in
    from tests.unit.brdf.reconstruction.test_basis import small_basis
    from tests.unit.brdf.reconstruction.test_localprior import _grey, _sharp
    from tests.unit.brdf.reconstruction.test_reconstruct import grid_pairs

    basis = fold_in(small_basis(), [_grey(), _sharp()], 4.0).save(tmp_path / "b.npz")
    cells, ph = grid_pairs(6, seed=11)
    pairs = tmp_path / "cells.csv"
    pairs.write_text("th,td,pd,ph\n" + "\n".join(
        ",".join(f"{v:g}" for v in np.rad2deg([*c, p])) for c, p in zip(cells, ph, strict=True)))
    table = _sharp().save(tmp_path / "sharp.npz")
    samples = tmp_path / "s.npz"
    assert main(["simulate-scan", "--table", str(table), "--pairs", str(pairs),
                 "--rotations", "8", "--seed", "3", "-o", str(samples)]) == 0
    capsys.readouterr()
    assert main(["reconstruct", str(samples), "--basis", str(basis),
                 "-o", str(tmp_path / "rec.npz")]) == 0
    out = capsys.readouterr().out
    assert "prior: leaned on sharp where no pair looks" in out
    bare = small_basis().save(tmp_path / "bare.npz")
    assert main(["reconstruct", str(samples), "--basis", str(bare),
                 "-o", str(tmp_path / "rec2.npz")]) == 0
    assert "prior:" not in capsys.readouterr().out
    # --local-prior none keeps the library's prior with the same basis.
    assert main(["reconstruct", str(samples), "--basis", str(basis), "--local-prior", "none",
                 "-o", str(tmp_path / "rec3.npz")]) == 0
    assert "prior:" not in capsys.readouterr().out
