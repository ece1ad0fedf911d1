"""Tests of the render weight's writer (gonio.brdf.pictures.designweight): the shipped map
is what the standard renderings count, and the design room reads what the writer writes."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from gonio.brdf.design.renderweight import read_render_weight, render_weight
from gonio.brdf.pictures import appearance, designweight


def test_the_shipped_map_is_the_standard_renderings_count() -> None:
    """Fails after a change to the standard renderings until the file is written again."""
    counted = appearance.render_importance()
    assert np.array_equal(render_weight(), counted), (
        "the design's shipped render weight is not the standard renderings' count: run "
        "`python -m gonio.brdf.pictures.designweight` and commit the file it writes")


def test_what_the_writer_writes_the_design_room_reads(tmp_path: Path) -> None:
    rng = np.random.default_rng(3)
    counts = np.where(rng.random((18, 18, 36)) < 0.2, rng.random((18, 18, 36)) * 40, 0.0)
    path = tmp_path / "w.npz"
    designweight.write_render_weight(path, counts, designweight.views_description())
    assert np.array_equal(read_render_weight(str(path)), counts)
    with np.load(path) as z:
        views = json.loads(str(z["views"]))
    # The four lights of the standard renderings, as docs/science.md 7 names them.
    assert [v["polar_deg"] for v in views["views"]] == [20.0, 55.0, 55.0, 70.0]
    assert [v["azimuth_deg"] for v in views["views"]] == [135.0, 0.0, 90.0, 45.0]
    assert views["size"] == 96


def test_the_writer_refuses_a_map_of_another_shape(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match=r"has shape \(18, 18, 36\)"):
        designweight.write_render_weight(tmp_path / "w.npz", np.zeros((18, 18, 72)), {})


def test_the_writer_writes_to_the_design_package_by_default(tmp_path: Path) -> None:
    assert designweight.shipped_path().parts[-3:] == ("design", "data", "render-importance.npz")
    out = tmp_path / "here.npz"
    assert designweight.main([str(out)]) == 0
    assert np.array_equal(read_render_weight(str(out)), appearance.render_importance())


def test_the_writer_says_the_name_it_writes_and_has_help(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """numpy adds .npz to a name without it; the printed path is the file on disk."""
    assert designweight.main([str(tmp_path / "plain")]) == 0
    assert (tmp_path / "plain.npz").is_file()
    assert f"wrote {tmp_path / 'plain.npz'}" in capsys.readouterr().out
    with pytest.raises(SystemExit) as exc:
        designweight.main(["--help"])
    assert exc.value.code == 0
    assert "usage: python -m gonio.brdf.pictures.designweight" in capsys.readouterr().out
