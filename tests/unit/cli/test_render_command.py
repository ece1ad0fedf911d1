"""'gonio render' (gonio.cli.render_command): a table rendered to PNG, and bad inputs."""

from __future__ import annotations

from pathlib import Path

import pytest
from PIL import Image

from gonio.brdf.models import analytic as bm
from gonio.brdf.pictures import render as R  # noqa: N812 (short name for many calls)
from gonio.cli import main as cli_main


def test_cli_render_table_and_bad_inputs(tmp_path: Path, capsys: pytest.CaptureFixture[str]
                                         ) -> None:
    table = bm.tabulate(bm.GGX(alpha_x=0.1, alpha_y=0.4, name="brushed"))
    src = table.save(tmp_path / "brushed.npz")
    out = tmp_path / "r.png"
    assert cli_main(["render", str(src), "-o", str(out), "--size", "64"]) == 0
    im = Image.open(out)
    assert im.width >= len(R.DEFAULT_VIEWS) * 64
    assert cli_main(["render", str(tmp_path / "none.h5"), "-o", str(out)]) == 2
    assert "does not exist" in capsys.readouterr().err
    assert cli_main(["render", str(src), "-o", str(tmp_path / "no" / "r.png")]) == 2
    assert "folder" in capsys.readouterr().err
    assert cli_main(["render", str(src), "-o", str(out), "--size", "5"]) == 2
    assert "--size" in capsys.readouterr().err
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"not a table")
    assert cli_main(["render", str(bad), "-o", str(out)]) == 2
    # An existing picture is not replaced without --overwrite (it was, without a word).
    before = out.read_bytes()
    capsys.readouterr()
    assert cli_main(["render", str(src), "-o", str(out), "--size", "96"]) == 2
    assert f"{out} exists: the rendering was not written" in capsys.readouterr().err
    assert out.read_bytes() == before
    assert cli_main(["render", str(src), "-o", str(out), "--size", "96", "--overwrite"]) == 0
    assert out.read_bytes() != before


def test_files_that_are_not_results_are_named_for_what_they_are(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A newcomer's slips: a table exported as `-o felt.table` (no .npz), a rig config and an
    empty HDF5 file given as results. They read "is not an HDF5 file or is damaged (Unable
    to synchronously open file (file signature not found))" and "(format None)"."""
    import h5py

    table = bm.tabulate(bm.GGX(alpha_x=0.1, alpha_y=0.4, name="brushed"))
    named = tmp_path / "felt.table"
    table.save(tmp_path / "t.npz").rename(named)
    out = tmp_path / "r.png"
    assert cli_main(["render", str(named), "-o", str(out), "--size", "64"]) == 0  # drawn
    capsys.readouterr()
    toml = tmp_path / "rig.toml"
    toml.write_text('[rig]\nname = "sim"\n')
    assert cli_main(["render", str(toml), "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert f"{toml} is not an HDF5 file, so not a gonio result file" in err, err
    assert "damaged" not in err and "signature" not in err and "'gonio scan -o'" in err, err
    other = tmp_path / "other.h5"
    h5py.File(other, "w").close()
    for command in ("render", "colour", "export"):
        argv = [command, str(other)] + (["-o", str(out)] if command == "render" else [])
        assert cli_main(argv + (["-f", "gltf"] if command == "export" else [])) == 2
        err = capsys.readouterr().err
        assert f"{other} is an HDF5 file but not a gonio result file" in err, err
        assert "None" not in err, err


def test_a_rendered_result_says_its_reconstructions_warnings(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """gonio colour and gonio export say a result's own warnings (the highlight not read,
    values outside physical bounds); gonio render drew the same result without a word."""
    import numpy as np

    from gonio.brdf.tables.table import from_function
    from gonio.calibration import CalibratedScan
    from gonio.results import write_result

    samples = CalibratedScan(pairs=[("L1", "S1")], light_dirs=np.array([[0.0, 0.0, 1.0]]),
                             sensor_dirs=np.array([[0.0, 0.0, 1.0]]),
                             stage_angles_deg=np.array([0.0]), values=np.ones((1, 1, 1)),
                             channels=("Y",))
    table = from_function(lambda i, o: np.full((i.shape[0], 1), 0.2), ["Y"], "x",
                          dtype=np.float32)
    bounds = "the reconstruction is outside physical bounds: its maximum is above 1000"
    warned = write_result(tmp_path / "warned.h5", job_id=3, specimen="red", kind="uniform",
                          readings=[], samples=samples, table=table,
                          provenance={"physical_bounds": bounds})
    plain = write_result(tmp_path / "plain.h5", job_id=4, specimen="red", kind="uniform",
                         readings=[], samples=samples, table=table)
    out = tmp_path / "r.png"
    assert cli_main(["render", str(warned), "-o", str(out), "--size", "64"]) == 0
    assert f"warning: {bounds}" in capsys.readouterr().err
    assert cli_main(["render", str(plain), "-o", str(out), "--size", "64", "--overwrite"]) == 0
    assert "warning" not in capsys.readouterr().err
    # Several inputs: each warning names its file.
    assert cli_main(["render", str(warned), str(plain), "-o", str(out), "--size", "64",
                     "--overwrite"]) == 0
    assert f"warning: warned.h5: {bounds}" in capsys.readouterr().err
