"""Tests of the shipped render weight and its reader (gonio.brdf.design.renderweight).

That the shipped map is the renderer's count is tests/unit/brdf/pictures/test_designweight.py.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from gonio.brdf.design.errors import DesignError
from gonio.brdf.design.renderweight import (
    DEFAULT_CELL_MIX,
    FORMAT,
    VERSION,
    read_render_weight,
    render_weight,
)
from gonio.brdf.tables import geometry as geo


def test_the_shipped_map_is_read_once_and_cannot_be_changed() -> None:
    w = render_weight()
    assert w.shape == geo.SLICE_SHAPE and w is render_weight()
    assert np.all(w >= 0) and w.sum() > 0
    with pytest.raises(ValueError, match="read-only"):
        w[0, 0, 0] = 1.0
    assert 0.0 < DEFAULT_CELL_MIX <= 1.0


def _write(path: Path, **override: object) -> Path:
    fields: dict[str, object] = {
        "format": np.array(FORMAT), "version": np.array(VERSION),
        "shape": np.array(geo.SLICE_SHAPE), "index": np.array([0, 7, 11663], dtype=np.int32),
        "value": np.array([1.0, 2.5, 0.25]), "views": np.array("{}")}
    fields.update(override)
    np.savez(path, **fields)  # type: ignore[arg-type]
    return path


def test_a_file_holds_the_counts_at_their_nodes(tmp_path: Path) -> None:
    w = read_render_weight(str(_write(tmp_path / "w.npz")))
    flat = w.reshape(-1)
    assert flat[0] == 1.0 and flat[7] == 2.5 and flat[11663] == 0.25
    assert np.count_nonzero(flat) == 3


@pytest.mark.parametrize(("override", "message"), [
    ({"format": np.array("gonio-brdf-basis")}, "is not a gonio-render-weight file of version 1"),
    ({"version": np.array(2)}, "is not a gonio-render-weight file of version 1"),
    ({"shape": np.array([18, 18, 72])}, r"holds a map of shape \(18, 18, 72\)"),
    ({"index": np.array([0, 7, 11664])}, "bad indices or counts"),
    ({"index": np.array([0, 7, 7])}, "bad indices or counts"),
    ({"value": np.array([1.0, np.nan, 0.25])}, "bad indices or counts"),
    ({"value": np.array([1.0, -2.0, 0.25])}, "bad indices or counts"),
    ({"value": np.array([1.0, 2.0])}, "bad indices or counts"),
])
def test_a_bad_file_is_refused_with_how_to_write_it_again(
        tmp_path: Path, override: dict[str, object], message: str) -> None:
    path = _write(tmp_path / "w.npz", **override)
    with pytest.raises(DesignError, match=message) as exc:
        read_render_weight(str(path))
    assert "python -m gonio.brdf.pictures.designweight" in str(exc.value)


def test_a_missing_or_unreadable_file_is_a_design_error(tmp_path: Path) -> None:
    with pytest.raises(DesignError, match="cannot read the render-weight file"):
        read_render_weight(str(tmp_path / "none.npz"))
    junk = tmp_path / "junk.npz"
    junk.write_bytes(b"not a zip")
    with pytest.raises(DesignError, match="cannot read the render-weight file"):
        read_render_weight(str(junk))


def test_a_share_asked_for_becomes_the_designs_cell_weighting() -> None:
    from gonio.brdf.design.renderweight import cell_weighting

    assert cell_weighting(None) == {}
    assert cell_weighting(0) == {"cell_mix": 0.0}
    asked = cell_weighting(0.25)
    assert asked["cell_mix"] == 0.25 and asked["cell_weight"] is render_weight()
