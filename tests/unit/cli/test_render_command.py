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
