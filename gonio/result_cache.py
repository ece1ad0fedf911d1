"""The result views' one cache: result files read whole, and what views compute from them.

A finished result file is read and its views computed (the fit plot's curves, the polar plot's,
the preview and rendering PNGs) once while the file stays the same: every entry is keyed by the
identity of the file(s) it was made from (:class:`FileIdentity`: path, device, inode, size,
modification and change times, from ``os.stat``), checked on every request. A result file is
only ever replaced whole (``gonio jobs rebuild`` and finishing write a temporary file and
rename it over the old one, :mod:`gonio.atomicfile`), which gives it a new inode as well as
new times, so a rewritten file is a new key even when the file system's clock has not ticked
between the two writes. An entry is kept only when its files' identities after making it are
the ones they had before (a file replaced while it was being read is read again next time).

Bounded twice, least recently used first out: result files (a 31-band table alone is about
100 MB in memory: 839,808 cells x 31 channels in float32) by :data:`MAX_RESULTS` and
:data:`RESULT_BYTES`, and the views computed from them by :data:`MAX_VIEWS` and
:data:`VIEW_BYTES`. Thread-safe (the API serves from threads); requests for an entry that is
being made wait for it instead of reading the same file again (the lab page asks for several
views of a job together).
"""

from __future__ import annotations

import os
import sys
import threading
from collections import OrderedDict
from collections.abc import Callable, Hashable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar

import numpy as np

if TYPE_CHECKING:  # HDF5 loads with the first result read
    from gonio.results import ResultFile

T = TypeVar("T")

MAX_RESULTS = 2
"""Result files kept: the job on the page and the one it is compared with."""
RESULT_BYTES = 256 * 2**20
"""Bytes of result files kept: two 31-band results (about 105 MB each), or a few RGB ones."""
MAX_VIEWS = 32
"""Computed views kept (curves, PNGs), over all jobs and query parameters."""
VIEW_BYTES = 8 * 2**20
"""Bytes of computed views kept: a rendering is about 1 MB, a 31-band polar plot 0.7 MB in
memory, a fit plot 0.1 MB. More rendered figures kept the daemon growing scan after scan
(bench/bench_memory.py looks at every scan's views)."""

_SAMPLED = 256
"""A longer list or tuple is sized from this many of its items (a result's readings)."""


class _Missing:
    """What a shelf returns for a key it does not hold (None can be a value)."""


_MISSING = _Missing()


@dataclass(frozen=True)
class FileIdentity:
    """Which file is at a path now, as far as ``os.stat`` tells: a file replaced or rewritten
    has another inode, size, modification time or change time."""

    path: str
    device: int
    inode: int
    size: int
    mtime_ns: int
    ctime_ns: int

    @classmethod
    def of(cls, path: Path) -> FileIdentity:
        """The identity of the file at ``path``.

        Raises
        ------
        gonio.results.ResultFileError
            No file at ``path`` (it was removed).
        """
        try:
            st = os.stat(path)
        except FileNotFoundError:
            from gonio.results import ResultFileError

            raise ResultFileError(f"result file {path} does not exist") from None
        return cls(str(path), st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns, st.st_ctime_ns)


@dataclass(frozen=True)
class CacheStats:
    """What a :class:`ResultCache` holds and has done since it was made.

    ``reads`` counts result files read from disk (calls of the loader); ``hits`` and
    ``misses`` count look-ups of results and views alike; ``evictions`` entries dropped for
    the bounds; ``result_bytes`` and ``view_bytes`` are the estimated sizes held (bytes).
    """

    reads: int
    hits: int
    misses: int
    evictions: int
    results: int
    views: int
    result_bytes: int
    view_bytes: int


class _Shelf:
    """Entries under an entry bound and a byte bound, least recently used first out.
    Not locked: :class:`ResultCache` holds its lock around every call."""

    def __init__(self, max_entries: int, max_bytes: int) -> None:
        self.max_entries = max_entries
        self.max_bytes = max_bytes
        self.nbytes = 0
        self._items: OrderedDict[Hashable, tuple[Any, int]] = OrderedDict()

    def __len__(self) -> int:
        return len(self._items)

    def get(self, key: Hashable) -> Any:
        item = self._items.get(key)
        if item is None:
            return _MISSING
        self._items.move_to_end(key)
        return item[0]

    def put(self, key: Hashable, value: Any, nbytes: int) -> int:
        """Keep ``value`` (unless it alone is over the byte bound); the number evicted."""
        if nbytes > self.max_bytes or self.max_entries < 1:
            return 0
        old = self._items.pop(key, None)
        if old is not None:
            self.nbytes -= old[1]
        self._items[key] = (value, nbytes)
        self.nbytes += nbytes
        evicted = 0
        while len(self._items) > self.max_entries or self.nbytes > self.max_bytes:
            _, (_, size) = self._items.popitem(last=False)
            self.nbytes -= size
            evicted += 1
        return evicted

    def clear(self) -> None:
        self._items.clear()
        self.nbytes = 0


def _default_loader(path: Path) -> ResultFile:
    # Looked up at each call, so the reader is the one gonio.results has now.
    from gonio import results

    return results.read_result(path)


class ResultCache:
    """Result files read whole and the views computed from them, keyed by the files' identity.

    Parameters
    ----------
    max_results, result_bytes : int
        Result files kept, and their estimated bytes (a file over the byte bound alone is
        read and used, not kept).
    max_views, view_bytes : int
        Computed views kept, and their estimated bytes.
    loader : callable, optional
        Reads a result file whole (default :func:`gonio.results.read_result`); raises
        :class:`gonio.results.ResultFileError` for a file it cannot read.
    """

    def __init__(self, *, max_results: int = MAX_RESULTS, result_bytes: int = RESULT_BYTES,
                 max_views: int = MAX_VIEWS, view_bytes: int = VIEW_BYTES,
                 loader: Callable[[Path], ResultFile] | None = None) -> None:
        self.loader = loader or _default_loader
        self._lock = threading.Lock()
        self._results = _Shelf(max_results, result_bytes)
        self._views = _Shelf(max_views, view_bytes)
        # Entries being made: whoever asks for one of them waits for it.
        self._pending: dict[Hashable, threading.Event] = {}
        self._reads = self._hits = self._misses = self._evictions = 0

    def result(self, path: Path) -> ResultFile:
        """The result file at ``path``, read whole (once while it stays the same file).

        Blocking (reads the file): call it from a thread in async code. Callers must not
        change what it returns: it is shared.

        Raises
        ------
        gonio.results.ResultFileError
            The file is missing or cannot be read (from the loader).
        """
        ident = FileIdentity.of(path)
        return self._get(self._results, ("result", ident), (path,), (ident,),
                         lambda: self._read(path))

    def view(self, name: str, params: Hashable, paths: Sequence[Path],
             make: Callable[[], T]) -> T:
        """What ``make()`` computes from the result files at ``paths`` for ``params``, made
        once while those files stay the same.

        Blocking (``make`` runs here): call it from a thread in async code. Callers must not
        change what it returns: it is shared.

        Parameters
        ----------
        name : which view (``"fit"``, ``"polar"``, ...)
        params : the view's query parameters (hashable, e.g. a tuple of floats)
        paths : the result files the view is computed from
        make : computes the view; what it raises reaches the caller, and nothing is kept

        Raises
        ------
        gonio.results.ResultFileError
            A file at ``paths`` is missing; or what ``make`` raises.
        """
        files = tuple(paths)
        idents = tuple(FileIdentity.of(p) for p in files)
        return self._get(self._views, (name, params, idents), files, idents, make)

    def stats(self) -> CacheStats:
        """Counters and sizes (:class:`CacheStats`)."""
        with self._lock:
            return CacheStats(self._reads, self._hits, self._misses, self._evictions,
                              len(self._results), len(self._views), self._results.nbytes,
                              self._views.nbytes)

    def clear(self) -> None:
        """Forget every entry (the counters stay)."""
        with self._lock:
            self._results.clear()
            self._views.clear()

    def _read(self, path: Path) -> ResultFile:
        with self._lock:
            self._reads += 1
        return self.loader(path)

    def _get(self, shelf: _Shelf, key: Hashable, files: tuple[Path, ...],
             idents: tuple[FileIdentity, ...], make: Callable[[], T]) -> T:
        while True:
            with self._lock:
                found = shelf.get(key)
                if found is not _MISSING:
                    self._hits += 1
                    return found
                waiting = self._pending.get(key)
                if waiting is None:
                    done = self._pending[key] = threading.Event()
                    self._misses += 1
                    break
            # Being made by another thread: take it from the shelf when it is there (or, if
            # that failed or was not kept, make it here).
            waiting.wait()
        try:
            value = make()
            if _identities(files) == idents:
                nbytes = approx_nbytes(value)
                with self._lock:
                    self._evictions += shelf.put(key, value, nbytes)
            return value
        finally:
            with self._lock:
                del self._pending[key]
            done.set()


def _identities(files: tuple[Path, ...]) -> tuple[FileIdentity, ...] | None:
    """The files' identities now; None when one has gone."""
    try:
        return tuple(FileIdentity.of(p) for p in files)
    except ValueError:  # ResultFileError: removed while the entry was made
        return None


def approx_nbytes(value: Any) -> int:
    """Estimated memory held by ``value``: NumPy arrays by their data, Python objects by
    ``sys.getsizeof`` through containers, dataclasses and instance attributes (each object
    once). A list or tuple longer than a few hundred items is sized from a sample of them.

    Returns
    -------
    int : bytes
    """
    seen: set[int] = set()
    total = 0.0
    stack: list[tuple[Any, float]] = [(value, 1.0)]
    while stack:
        obj, weight = stack.pop()
        if id(obj) in seen:
            continue
        seen.add(id(obj))
        if isinstance(obj, np.ndarray):
            total += weight * (obj.nbytes + sys.getsizeof(np.empty(0)))
            continue
        total += weight * sys.getsizeof(obj)
        if isinstance(obj, str | bytes | bytearray | int | float | complex | bool) or obj is None:
            continue
        if isinstance(obj, dict):
            stack.extend((x, weight) for kv in obj.items() for x in kv)
        elif isinstance(obj, list | tuple | set | frozenset):
            items = list(obj) if not isinstance(obj, list | tuple) else obj
            if len(items) > _SAMPLED:
                step = len(items) / _SAMPLED
                stack.extend((items[int(i * step)], weight * step) for i in range(_SAMPLED))
            else:
                stack.extend((x, weight) for x in items)
        elif hasattr(obj, "__dict__"):
            stack.append((vars(obj), weight))
        elif hasattr(obj, "__slots__"):
            stack.extend((getattr(obj, s), weight) for s in obj.__slots__ if hasattr(obj, s))
    return int(total)
