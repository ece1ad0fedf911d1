"""The MERL .binary reader against files written byte by byte from the published layout:
three little-endian int32 dimensions, then the red, green and blue float64 blocks in C order,
scaled by 1/1500, 1.15/1500 and 1.66/1500; negative numbers are cells without data."""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np
import pytest

from gonio.brdf.materials.merl import MerlError, read_merl_values


def merl_bytes(dims: tuple[int, int, int], values: list[float]) -> bytes:
    return struct.pack("<3i", *dims) + struct.pack(f"<{len(values)}d", *values)


def test_a_small_file_reads_in_the_published_layout(tmp_path: Path) -> None:
    dims = (2, 2, 3)
    n = 12
    stored = [float(i) for i in range(3 * n)]
    stored[n + 5] = -1.0  # a green cell without data
    path = tmp_path / "tiny.binary"
    path.write_bytes(merl_bytes(dims, stored))
    out = read_merl_values(path, shape=None)
    assert out.shape == (3, 2, 2, 3)
    # red cell (1, 0, 2) is the stored number 1*6 + 0*3 + 2 = 8, over 1500
    assert out[0, 1, 0, 2] == pytest.approx(8 / 1500)
    # blue cell (0, 1, 1) is 2n + 4 = 28, times 1.66/1500
    assert out[2, 0, 1, 1] == pytest.approx(28 * 1.66 / 1500)
    assert np.isnan(out[1, 0, 1, 2])  # green index 5 = (0, 1, 2)
    assert np.isnan(out).sum() == 1


def test_the_database_shape_is_required_by_default(tmp_path: Path) -> None:
    path = tmp_path / "small.binary"
    path.write_bytes(merl_bytes((2, 2, 3), [0.0] * 36))
    with pytest.raises(MerlError, match=r"dimensions \(2, 2, 3\), expected \(90, 90, 180\)"):
        read_merl_values(path)


@pytest.mark.parametrize(("content", "message"), [
    (b"\x01\x02", "2 bytes is too short for a MERL .binary file"),
    (merl_bytes((2, 2, 3), [0.0] * 35), "needs 300; the file is truncated"),
    (merl_bytes((1, 2, 3), [0.0] * 18), r"header dimensions \[1, 2, 3\] are not a MERL table"),
    (struct.pack("<3i", 1000, 1000, 1000), "are not a MERL table"),
    (b"<html>not a brdf</html>", "are not a MERL table"),
])
def test_what_is_not_a_merl_file_is_refused(tmp_path: Path, content: bytes,
                                            message: str) -> None:
    path = tmp_path / "bad.binary"
    path.write_bytes(content)
    with pytest.raises(MerlError, match=message):
        read_merl_values(path, shape=None)


def test_a_missing_file(tmp_path: Path) -> None:
    with pytest.raises(MerlError, match=r"cannot be read \(No such file or directory\)"):
        read_merl_values(tmp_path / "none.binary")
