"""Every example in docs/file-formats.md parses with gonio's own readers.

Text formats (pairs files, design fragment, rig and daemon configs, keys file, calibration)
are written to a file and read by the function gonio uses for them. For binary formats the
documented snippet runs as written: reading snippets against a file gonio wrote, the samples
writing snippet to make a file gonio then reads.
"""

from __future__ import annotations

import math
import os
import re
import sqlite3
from pathlib import Path

import numpy as np
import pytest

from gonio.brdf.tables import geometry as geo

DOC = Path(__file__).resolve().parents[2] / "docs" / "file-formats.md"


def examples() -> dict[str, str]:
    """``<!-- example: NAME -->`` followed by a fenced block -> {NAME: block text}."""
    text = DOC.read_text(encoding="utf-8")
    found = re.findall(r"<!-- example: ([\w-]+) -->\n```[\w]*\n(.*?)```", text, re.S)
    names = [n for n, _ in found]
    assert len(names) == len(set(names)), f"repeated example names: {names}"
    return dict(found)


EXPECTED = {
    "table-read", "basis-read", "samples-write", "pairs-csv", "pairs-cells-csv", "pairs-json",
    "pairs-toml", "design-fragment", "rig-config", "daemon-config", "keys-file",
    "calibration", "result-read", "job-store",
}


def test_every_documented_format_has_an_example_and_each_is_tested() -> None:
    assert set(examples()) == EXPECTED


@pytest.fixture
def in_tmp(tmp_path: Path) -> object:
    old = Path.cwd()
    os.chdir(tmp_path)
    try:
        yield tmp_path
    finally:
        os.chdir(old)


def _run(code: str) -> dict[str, object]:
    scope: dict[str, object] = {}
    exec(compile(code, str(DOC), "exec"), scope)  # the documented snippet, as written
    return scope


def test_table_read_snippet_reads_a_gonio_table(in_tmp: Path,
                                                capsys: pytest.CaptureFixture[str]) -> None:
    from gonio.brdf.models.analytic import Lambert, tabulate

    tabulate(Lambert((0.2, 0.4, 0.6), name="felt")).save("felt.npz")
    _run(examples()["table-read"])
    out = capsys.readouterr().out.splitlines()
    assert out[0].startswith("felt ['R', 'G', 'B'] analytic")
    assert float(out[1]) == pytest.approx(0.4 / math.pi, rel=1e-6)  # G of a Lambertian


def test_basis_read_snippet_reads_a_gonio_basis(in_tmp: Path,
                                                capsys: pytest.CaptureFixture[str]) -> None:
    from gonio.brdf.reconstruction.basis import Basis

    rng = np.random.default_rng(0)
    valid = geo.valid_mask().ravel()
    Q = rng.normal(size=(geo.N_ROWS, 5)) * valid[:, None]
    Basis(Q, np.linspace(3, 1, 5), np.ones(geo.N_ROWS), np.zeros(geo.N_ROWS),
          valid).save("basis.npz")
    _run(examples()["basis-read"])
    out = capsys.readouterr().out
    assert out.strip() == f"gonio-brdf-basis ({geo.N_ROWS}, 5) {int(valid.sum())} valid rows, " \
        "5 components"


def test_samples_written_with_numpy_alone_load_in_gonio(in_tmp: Path) -> None:
    from gonio.brdf.reconstruction.samples import Samples

    _run(examples()["samples-write"])
    s = Samples.load("samples.npz")
    assert s.values.shape == (2, 4, 1) and s.channels == ("Y",)
    np.testing.assert_allclose(np.degrees(s.cells[1]), [35, 25, 0])
    np.testing.assert_allclose(np.degrees(s.stage_angles), [0, 90, 180, 270])
    assert s.provenance["source"] == "my instrument"


@pytest.mark.parametrize(("name", "suffix"), [("pairs-csv", ".csv"), ("pairs-json", ".json"),
                                              ("pairs-toml", ".toml")])
def test_lab_direction_pairs_files(tmp_path: Path, name: str, suffix: str) -> None:
    from gonio.cli.brdf_commands import read_pairs

    path = tmp_path / f"pairs{suffix}"
    path.write_text(examples()[name])
    cells, ph = read_pairs(path)
    # Independently: light (45, 0) and view (30, 180) are mirror directions in one plane, so
    # the half vector lies in that plane at (45 - 30) / 2 = 7.5 deg from the normal, toward
    # the light's azimuth 0, and the difference angle is half the 75 deg between them.
    assert np.degrees(cells[0, 0]) == pytest.approx(7.5)
    assert np.degrees(cells[0, 1]) == pytest.approx(37.5)
    assert np.degrees(ph[0]) % 360 == pytest.approx(0.0, abs=1e-9)
    assert cells.shape == ((2, 3) if name != "pairs-toml" else (1, 3))


def test_cell_pairs_file(tmp_path: Path) -> None:
    from gonio.cli.brdf_commands import read_pairs

    path = tmp_path / "cells.csv"
    path.write_text(examples()["pairs-cells-csv"])
    cells, ph = read_pairs(path)
    np.testing.assert_allclose(np.degrees(cells), [[10, 20, 90], [30, 5, 45]])
    np.testing.assert_allclose(np.degrees(ph), [0, 120])


def test_design_fragment(tmp_path: Path) -> None:
    from gonio.cli.brdf_commands import read_pairs
    from gonio.rigdesign import load_fragment

    path = tmp_path / "geometry.toml"
    path.write_text(examples()["design-fragment"])
    design = load_fragment(path)
    assert design.pair_names() == [("L1", "S1"), ("L2", "S2")]
    assert design.light("L2").theta_deg == 55.0
    assert design.design is not None and design.design.rotations == 8  # [design] reads
    assert read_pairs(path)[0].shape == (2, 3)


def test_rig_config(tmp_path: Path) -> None:
    from gonio.config import load_rig_config

    path = tmp_path / "rig.toml"
    path.write_text(examples()["rig-config"])
    cfg = load_rig_config(path)
    assert cfg.stage.driver == "zaber" and [p.light for p in cfg.pair_list()] == ["L1"]
    assert cfg.sensor("S1").registers.exposure.scale == 1e-6


def test_daemon_config_and_keys_file(tmp_path: Path) -> None:
    from gonio.apikeys import parse_keys_file
    from gonio.daemon import load_daemon_config, load_keyring

    (tmp_path / "daemon.toml").write_text(examples()["daemon-config"])
    (tmp_path / "api-keys").write_text(examples()["keys-file"])
    (tmp_path / "api-keys").chmod(0o600)
    cfg = load_daemon_config(tmp_path / "daemon.toml")
    assert cfg.server.port == 8600 and cfg.auth.keys_file == tmp_path / "api-keys"
    assert cfg.paths.data_dir == Path("/var/lib/gonio")
    keys = parse_keys_file(examples()["keys-file"], "api-keys")
    assert sorted(keys) == ["alice", "lab-pc"]
    assert sorted(load_keyring(cfg, environ={}).names) == ["alice", "lab-pc"]


def test_calibration_json() -> None:
    from gonio.calibration import Calibration

    cal = Calibration.model_validate_json(examples()["calibration"])
    assert cal.reference_albedo == 0.99 and cal.exposure_s == 0.01
    np.testing.assert_allclose(cal.factor("L1", "S2", 3), [5.32e-06, 5.32e-06, 5.31e-06])


def test_result_read_snippet_reads_a_gonio_result(in_tmp: Path,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    from gonio.calibration import Calibration, calibrated_samples
    from gonio.hal import PairSpec
    from gonio.results import write_result
    from gonio.store import ReadingRow

    readings = [ReadingRow(k, a, a, "L1", "S1", (11.0, 12.0, 13.0), (1.0, 1.0, 1.0), 0.01, 1,
                           False, 1.0) for k, a in enumerate((0.0, 180.0))]
    cal = Calibration(source="job 1: white reference")
    dirs = np.array([[0.0, 0.0, 1.0]])
    samples = calibrated_samples(readings, [PairSpec(light="L1", sensor="S1")], dirs, dirs,
                                 ("R", "G", "B"), cal)
    write_result("felt.h5", job_id=2, specimen="felt", kind="calibration", readings=readings,
                 samples=samples)
    _run(examples()["result-read"])
    out = capsys.readouterr().out.splitlines()
    assert out[0] == "gonio-result 2 calibration"
    assert out[1] == "(1, 2, 3) [0.0, 180.0] job 1: white reference"


def test_job_store_snippet_reads_a_gonio_store(in_tmp: Path,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    from gonio.store import JobStore

    store = JobStore(Path("gonio.sqlite"))
    store.create_job(kind="uniform", specimen="felt", plan={"kind": "uniform"}, rig={})
    scope = _run(examples()["job-store"])
    assert capsys.readouterr().out.strip() == "1 queued uniform uniform None"
    assert scope["n"] == 0
    assert isinstance(scope["db"], sqlite3.Connection)
