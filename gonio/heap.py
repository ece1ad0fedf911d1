"""Keeping the daemon's heap from growing scan after scan (glibc's malloc).

A reconstruction allocates and frees arrays of tens of MB, in several threads (finishing runs
in a thread pool, renders in the API's). glibc serves a large allocation with ``mmap`` and
gives it back to the system when freed, but each such free also *raises* its mmap threshold
to the freed size (up to 32 MB): from then on arrays of that size come from the heaps of the
threads' arenas, where freed memory stays mapped and fragments. Measured with
``bench/bench_memory.py``: the daemon grew from 605 MB after the first scan to 865 MB after
the tenth. Fixing the threshold at glibc's own starting value stops the raising (``mallopt``
with an explicit ``M_MMAP_THRESHOLD`` disables the adjustment), few arenas keep the threads
from each holding a heap of their own, and a trim after each job hands back what the arenas
still hold.

Elsewhere than glibc (macOS, musl) both are no-ops.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import logging
import sys
from typing import Any

log = logging.getLogger("gonio.heap")

M_MMAP_THRESHOLD = -3
"""``mallopt`` parameter number of the mmap threshold (glibc ``malloc.h``)."""
M_ARENA_MAX = -8
"""``mallopt`` parameter number of the most arenas (glibc ``malloc.h``)."""
ARENA_MAX = 2
"""Arenas the process may use: glibc's default (8 per core) lets every thread of the pools
(finishing, request handlers) fill a heap of its own over the first scans."""
MMAP_THRESHOLD_BYTES = 128 * 1024
"""Allocations from this size up are mapped on their own and unmapped when freed: glibc's
initial threshold, kept fixed."""

_libc: Any = None
_bounded = False


def _glibc() -> Any:
    global _libc
    if _libc is None:
        _libc = False
        if sys.platform.startswith("linux"):
            name = ctypes.util.find_library("c")
            try:
                lib = ctypes.CDLL(name or "libc.so.6")
            except OSError:
                return None
            if hasattr(lib, "mallopt") and hasattr(lib, "malloc_trim"):
                _libc = lib
    return _libc or None


def bound_heap() -> bool:
    """Fix glibc's mmap threshold and bound its arenas for this process (see module doc);
    True when done. Call early, before threads allocate."""
    global _bounded
    lib = _glibc()
    if lib is None:
        return False
    ok = True
    for param, value in ((M_MMAP_THRESHOLD, MMAP_THRESHOLD_BYTES), (M_ARENA_MAX, ARENA_MAX)):
        if not lib.mallopt(ctypes.c_int(param), ctypes.c_int(value)):
            log.debug("mallopt(%d, %d) refused; the heap may grow across scans", param, value)
            ok = False
    _bounded = _bounded or ok
    return ok


def heap_bounded() -> bool:
    """Whether :func:`bound_heap` fixed this process's mmap threshold: then every array of
    128 KiB or more is mapped afresh and its pages zeroed by the kernel on first touch, which
    doubles the CPU of work that makes thousands of them (the export fits:
    docs/notes/2026-11-27-export-cpu.md; :mod:`gonio.export.child` runs those elsewhere)."""
    return _bounded


def trim() -> None:
    """Give freed heap memory back to the system (glibc ``malloc_trim``); a no-op elsewhere."""
    lib = _glibc()
    if lib is not None:
        lib.malloc_trim(ctypes.c_size_t(0))
