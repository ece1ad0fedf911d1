"""The result views' cache (gonio.result_cache): a file is read once while it stays the same
file, a replaced or removed one is never answered from the cache, the bounds evict, and
threads asking at once share one read. The HTTP side (real result files from the simulated
rig, the routes on loopback): tests/system/api/test_cached_views.py."""

from __future__ import annotations

import json
import os
import sys
import threading
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from gonio.atomicfile import write_atomically
from gonio.result_cache import FileIdentity, ResultCache, approx_nbytes
from gonio.results import ResultFileError, read_result
from tests.unit.test_figures import _result, _table


class Disk:
    """A loader that reads a JSON file from disk and counts its reads (the boundary)."""

    def __init__(self) -> None:
        self.reads: list[Path] = []

    def __call__(self, path: Path) -> Any:
        self.reads.append(path)
        try:
            return json.loads(path.read_text())
        except (OSError, ValueError) as exc:
            raise ResultFileError(f"{path} does not read ({exc})") from None


def _write(path: Path, content: Any) -> Path:
    # As finishing and `gonio jobs rebuild` write result files: whole, then renamed.
    return write_atomically(path, json.dumps(content))


def test_a_result_is_read_once_while_it_stays_the_same_file(tmp_path: Path) -> None:
    disk = Disk()
    cache = ResultCache(loader=disk)
    path = _write(tmp_path / "a.json", {"v": 1})
    first = cache.result(path)
    assert cache.result(path) is first and first == {"v": 1}
    assert disk.reads == [path]
    st = cache.stats()
    assert (st.reads, st.hits, st.misses, st.results) == (1, 1, 1, 1)


def test_a_replaced_file_is_read_again_even_with_its_old_size_and_times(tmp_path: Path) -> None:
    disk = Disk()
    cache = ResultCache(loader=disk)
    path = _write(tmp_path / "a.json", {"v": 1})
    before = os.stat(path)
    assert cache.result(path) == {"v": 1}
    # Rewritten as gonio rewrites a result, same length, and its modification time set back
    # to the old one (a coarse file-system clock): the new inode still tells it apart.
    _write(path, {"v": 2})
    os.utime(path, ns=(before.st_atime_ns, before.st_mtime_ns))
    assert os.stat(path).st_size == before.st_size
    assert cache.result(path) == {"v": 2}
    assert len(disk.reads) == 2


def test_a_view_is_made_once_and_again_when_its_file_changes(tmp_path: Path) -> None:
    disk = Disk()
    cache = ResultCache(loader=disk)
    path = _write(tmp_path / "a.json", {"v": 3})
    made: list[float] = []

    def doubled(scale: float) -> dict[str, float]:
        made.append(scale)
        return {"v": cache.result(path)["v"] * scale}  # type: ignore[index]

    assert cache.view("doubled", (2.0,), [path], lambda: doubled(2.0)) == {"v": 6.0}
    assert cache.view("doubled", (2.0,), [path], lambda: doubled(2.0)) == {"v": 6.0}
    assert cache.view("doubled", (3.0,), [path], lambda: doubled(3.0)) == {"v": 9.0}
    assert made == [2.0, 3.0] and len(disk.reads) == 1
    _write(path, {"v": 5})
    assert cache.view("doubled", (2.0,), [path], lambda: doubled(2.0)) == {"v": 10.0}
    assert made == [2.0, 3.0, 2.0] and len(disk.reads) == 2


def test_a_removed_file_is_never_answered_from_the_cache(tmp_path: Path) -> None:
    cache = ResultCache(loader=Disk())
    path = _write(tmp_path / "a.json", {"v": 1})
    cache.result(path)
    cache.view("v", (), [path], lambda: 1)
    path.unlink()
    with pytest.raises(ResultFileError, match="does not exist"):
        cache.result(path)
    with pytest.raises(ResultFileError, match="does not exist"):
        cache.view("v", (), [path], lambda: 1)


def test_a_file_that_does_not_read_is_not_kept(tmp_path: Path) -> None:
    disk = Disk()
    cache = ResultCache(loader=disk)
    path = tmp_path / "bad.json"
    path.write_text("{not json")
    for _ in range(2):
        with pytest.raises(ResultFileError, match="does not read"):
            cache.result(path)
    assert len(disk.reads) == 2 and cache.stats().results == 0


def test_a_view_made_while_its_file_was_replaced_is_not_kept(tmp_path: Path) -> None:
    cache = ResultCache(loader=Disk())
    path = _write(tmp_path / "a.json", {"v": 1})
    calls = []

    def make() -> int:
        calls.append(1)
        if len(calls) == 1:
            _write(path, {"v": 2})  # replaced while the view is being made
        return len(calls)

    assert cache.view("n", (), [path], make) == 1
    assert cache.view("n", (), [path], make) == 2  # not kept: made again for the new file
    assert cache.view("n", (), [path], make) == 2


def test_the_entry_bound_evicts_the_least_recently_used(tmp_path: Path) -> None:
    disk = Disk()
    cache = ResultCache(max_results=2, loader=disk)
    a, b, c = (_write(tmp_path / f"{n}.json", {"n": n}) for n in "abc")
    cache.result(a)
    cache.result(b)
    cache.result(a)  # a used last: b is the one to go
    cache.result(c)
    assert cache.stats().evictions == 1 and cache.stats().results == 2
    cache.result(a)
    cache.result(c)
    assert disk.reads == [a, b, c]
    cache.result(b)
    assert disk.reads == [a, b, c, b]


def test_the_byte_bound_evicts_and_keeps_nothing_larger_than_itself(tmp_path: Path) -> None:
    path = _write(tmp_path / "a.json", {})
    blob = sys.getsizeof(b"x" * 1000)  # what a 1000-byte PNG is counted as
    cache = ResultCache(max_views=100, view_bytes=2 * blob + blob // 2, loader=Disk())
    for n in range(3):
        cache.view("png", (n,), [path], lambda: b"x" * 1000)
    st = cache.stats()
    assert (st.views, st.view_bytes, st.evictions) == (2, 2 * blob, 1)
    made: list[str] = []

    def png(name: str, size: int) -> bytes:
        made.append(name)
        return b"x" * size

    cache.view("png", (0,), [path], lambda: png("first", 1000))
    assert made == ["first"]  # the first went
    for _ in range(2):  # over the bound alone: used, not kept
        cache.view("big", (), [path], lambda: png("big", 3 * blob))
    assert made == ["first", "big", "big"] and cache.stats().views == 2


def test_threads_asking_at_once_share_one_read(tmp_path: Path) -> None:
    path = _write(tmp_path / "a.json", {"v": 1})
    go = threading.Event()
    reads: list[int] = []

    def slow(p: Path) -> Any:
        reads.append(1)
        go.wait(30)
        return json.loads(p.read_text())

    cache = ResultCache(loader=slow)
    got: list[Any] = []
    threads = [threading.Thread(target=lambda: got.append(cache.result(path)))
               for _ in range(8)]
    for t in threads:
        t.start()
    go.set()
    for t in threads:
        t.join(30)
    assert len(got) == 8 and all(g is got[0] for g in got) and got[0] == {"v": 1}
    assert reads == [1]


def test_a_real_result_file_is_read_by_read_result_and_sized(tmp_path: Path) -> None:
    cache = ResultCache()
    path = _result(tmp_path, table=_table())
    res = cache.result(path)
    assert res.table is not None
    np.testing.assert_array_equal(res.table.values, read_result(path).table.values)  # type: ignore[union-attr]
    assert cache.result(path) is res and cache.stats().reads == 1
    # At least its table: 3 channels x 839,808 cells of float32 (a constant table's NaN
    # cells included), and not much more for one pair's three samples.
    table_bytes = 3 * 72 * 18 * 18 * 36 * 4
    assert table_bytes <= cache.stats().result_bytes < table_bytes + 2**20


def test_sizes_count_arrays_by_their_data_and_long_lists_by_a_sample() -> None:
    a = np.zeros(10**6)
    assert 8 * 10**6 <= approx_nbytes(a) < 8 * 10**6 + 1000
    floats = [float(i) + 0.5 for i in range(10_000)]
    exact = sys.getsizeof(floats) + sum(sys.getsizeof(x) for x in floats)
    assert approx_nbytes(floats) == exact
    shared = np.ones(1000)
    assert approx_nbytes({"a": shared, "b": shared}) < 2 * shared.nbytes


def test_an_identity_names_the_file_and_says_when_it_is_gone(tmp_path: Path) -> None:
    path = _write(tmp_path / "a.json", {})
    ident = FileIdentity.of(path)
    assert ident.path == str(path) and ident.size == path.stat().st_size
    assert ident.inode == path.stat().st_ino
    path.unlink()
    with pytest.raises(ResultFileError, match=f"{path.name} does not exist"):
        FileIdentity.of(path)
