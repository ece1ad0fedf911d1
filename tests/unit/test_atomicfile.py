"""Files written whole or not at all (gonio.atomicfile)."""

from __future__ import annotations

from pathlib import Path

import pytest

from gonio.atomicfile import write_atomically


def test_the_file_holds_exactly_what_was_written(tmp_path: Path) -> None:
    target = tmp_path / "a.json"
    assert write_atomically(target, "Δ {}\n") == target
    assert target.read_bytes() == "Δ {}\n".encode()
    write_atomically(target, b"\x00\x01", sync_dir=True)  # replaces the old content whole
    assert target.read_bytes() == b"\x00\x01"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.json"]


def test_a_failed_write_leaves_what_was_there_and_no_temporary(tmp_path: Path) -> None:
    # A folder where the file should go: the rename fails after the data were written.
    (tmp_path / "taken").mkdir()
    with pytest.raises(OSError):
        write_atomically(tmp_path / "taken", b"new")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["taken"]


def test_a_failed_write_names_the_file_asked_for_not_the_temporary(tmp_path: Path) -> None:
    """`gonio export -o ro/x.gltf` into a folder it may not write said
    "ro/x.gltf.10a9bef722b0.part: Permission denied": a name the user never gave. The error
    names the target; the folder case is the same path (the rename fails after the write)."""
    target = tmp_path / "taken"
    target.mkdir()
    with pytest.raises(OSError) as info:
        write_atomically(target, b"new")
    assert info.value.filename == str(target), info.value
    missing = tmp_path / "no" / "x.gltf"  # opening the temporary fails: no folder
    with pytest.raises(OSError) as info:
        write_atomically(missing, b"new")
    assert info.value.filename == str(missing) and ".part" not in str(info.value)
