"""Recognising a full disk from each library that reports one (gonio.diskspace)."""

from __future__ import annotations

import errno
import os
import sqlite3
from pathlib import Path

import pytest

from gonio.calibration import Calibration, PairCalibration, save_calibration
from gonio.diskspace import DiskFull, is_disk_full

DEV_FULL = Path("/dev/full")  # Linux: every write fails with ENOSPC (null(4))
needs_dev_full = pytest.mark.skipif(not DEV_FULL.exists(), reason="no /dev/full here")


def test_sqlite_full_is_a_full_disk() -> None:
    # SQLite refuses to grow past max_page_count with SQLITE_FULL, the code a full disk gives.
    db = sqlite3.connect(":memory:")
    db.execute("CREATE TABLE t (x BLOB)")
    db.execute("PRAGMA max_page_count = 2")
    with pytest.raises(sqlite3.OperationalError) as err:
        db.execute("INSERT INTO t VALUES (zeroblob(100000))")
    assert "full" in str(err.value)
    assert is_disk_full(err.value)
    with pytest.raises(sqlite3.OperationalError) as other:
        db.execute("SELECT * FROM no_such_table")
    assert not is_disk_full(other.value)


@needs_dev_full
def test_a_write_to_dev_full_is_a_full_disk_and_so_is_what_it_caused() -> None:
    with pytest.raises(OSError) as err, open(DEV_FULL, "wb", buffering=0) as f:
        f.write(b"x")
    assert err.value.errno == errno.ENOSPC and is_disk_full(err.value)
    try:
        try:
            raise err.value
        except OSError as exc:
            raise RuntimeError("finishing failed") from exc
    except RuntimeError as wrapped:
        assert is_disk_full(wrapped)
    assert not is_disk_full(FileNotFoundError(errno.ENOENT, "gone"))
    assert is_disk_full(OSError(errno.EDQUOT, "quota"))
    full = DiskFull("disk full: x could not be written")
    assert isinstance(full, OSError) and str(full) == "disk full: x could not be written"


@needs_dev_full
def test_a_calibration_that_meets_a_full_disk_keeps_the_old_one(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    path = tmp_path / "calibration.json"
    old = Calibration(pairs=(PairCalibration(light="L1", sensor="S1", factor=(2.0,)),),
                      reference_albedo=0.99, source="old")
    save_calibration(old, path)
    # The temporary file is the full device: the write fails as on a full disk. (Its name is
    # pinned so the device can sit there; the write itself is the real one.)
    import uuid

    import gonio.atomicfile

    fixed = uuid.UUID(int=0)
    monkeypatch.setattr(gonio.atomicfile.uuid, "uuid4", lambda: fixed)
    tmp_name = f"calibration.json.{fixed.hex[:12]}.part"
    os.symlink(DEV_FULL, tmp_path / tmp_name)
    new = Calibration(pairs=(PairCalibration(light="L1", sensor="S1", factor=(3.0,)),),
                      reference_albedo=0.99, source="new")
    with pytest.raises(OSError) as err:
        save_calibration(new, path)
    assert is_disk_full(err.value)
    assert Calibration.model_validate_json(path.read_text()) == old
    assert not (tmp_path / tmp_name).exists()
