"""gonio's .npz container: what it writes opens with numpy alone, and every kind of wrong file
is refused with a message that names the file and what it is."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from gonio.brdf.tables.npzfile import read_npz, write_npz


class ThingError(ValueError):
    pass


def read(path: Path, **kw: object) -> tuple[dict[str, np.ndarray], dict[str, object]]:
    args: dict[str, object] = dict(format_name="gonio-thing", version=2, required=["a"],
                                   error=ThingError, kind="thing",
                                   how_to_make="make one with 'gonio thing'")
    args.update(kw)
    return read_npz(path, **args)  # type: ignore[arg-type]


def test_written_arrays_and_provenance_read_back(tmp_path: Path) -> None:
    path = tmp_path / "t.npz"
    a = np.arange(6.0).reshape(2, 3)
    assert write_npz(path, "gonio-thing", 2, {"by": "test", "when": Path("x")}, a=a) == path
    with np.load(path) as z:  # numpy alone opens it
        assert str(z["format"]) == "gonio-thing" and int(z["version"]) == 2
        assert json.loads(str(z["provenance"])) == {"by": "test", "when": "x"}
    data, prov = read(path)
    np.testing.assert_array_equal(data["a"], a)
    assert prov == {"by": "test", "when": "x", "file": str(path)}
    assert [p.name for p in tmp_path.iterdir()] == ["t.npz"]  # no temporary file left


def test_a_failed_write_leaves_the_old_file(tmp_path: Path) -> None:
    path = tmp_path / "t.npz"
    write_npz(path, "gonio-thing", 2, {}, a=np.ones(2))
    with pytest.raises(TypeError):
        write_npz(path, "gonio-thing", 2, {}, a=object.__new__(type("NoArray", (), {
            "__array__": lambda self, *a, **k: (_ for _ in ()).throw(TypeError("no"))})))
    np.testing.assert_array_equal(read(path)[0]["a"], np.ones(2))
    assert [p.name for p in tmp_path.iterdir()] == ["t.npz"]


@pytest.mark.parametrize(("content", "message"), [
    (b"", "not a readable gonio thing file: the file is empty, not a .npz (zip) archive; "
          "make one with 'gonio thing'"),
    (b"\x89HDF\r\n\x1a\nrest", "it is an HDF5 file (a gonio result file?"),
    (b"\x93NUMPY\x01\x00", "it is a single .npy array"),
    (b"PK\x05\x06" + bytes(18), "it is an empty or unusual zip archive"),
    (b"hello world", r"it starts with the bytes b'hello wo'"),
    (b"PK\x03\x04garbage", "not a readable gonio thing file ("),
])
def test_what_is_not_a_npz_says_what_it_is(tmp_path: Path, content: bytes, message: str) -> None:
    path = tmp_path / "x.npz"
    path.write_bytes(content)
    with pytest.raises(ThingError) as exc:
        read(path)
    assert str(exc.value).startswith(f"{path}: ") and message in str(exc.value)


def test_a_missing_file_and_a_directory(tmp_path: Path) -> None:
    with pytest.raises(ThingError, match="no such thing file"):
        read(tmp_path / "none.npz")
    with pytest.raises(ThingError, match="is a directory, not a thing file"):
        read(tmp_path)


def test_a_pickled_array_is_refused_without_loading_it(tmp_path: Path) -> None:
    path = tmp_path / "p.npz"
    np.savez(path, format=np.array("gonio-thing"), version=np.array(2),
             a=np.array([{"x": 1}], dtype=object))
    with pytest.raises(ThingError, match="it holds Python objects, which gonio files never do"):
        read(path)


def test_wrong_format_version_or_fields(tmp_path: Path) -> None:
    path = tmp_path / "t.npz"
    write_npz(path, "gonio-other", 2, {}, a=np.ones(1))
    with pytest.raises(ThingError, match=r"not a gonio thing file \(missing "
                                         r"format='gonio-thing'\); make one with"):
        read(path)
    write_npz(path, "gonio-thing", 1, {}, a=np.ones(1))
    with pytest.raises(ThingError, match="thing format version 1; this gonio reads version 2"):
        read(path)
    write_npz(path, "gonio-thing", 2, {}, b=np.ones(1))
    with pytest.raises(ThingError, match=r"missing fields \['a'\]"):
        read(path)


def test_provenance_that_is_not_an_object_is_dropped(tmp_path: Path) -> None:
    path = tmp_path / "t.npz"
    for bad in ("not json", "[1, 2]"):
        np.savez(path, format=np.array("gonio-thing"), version=np.array(2), a=np.ones(1),
                 provenance=np.array(bad))
        assert read(path)[1] == {"file": str(path)}
