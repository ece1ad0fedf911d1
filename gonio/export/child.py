"""The export fits of a daemon, run in a fresh interpreter of their own.

``gonio serve`` fixes glibc's mmap threshold (:func:`gonio.heap.bound_heap`) so that the
daemon stops growing from scan to scan. The price falls on work that makes thousands of
arrays of 128 KiB and more: each is mapped afresh and its pages zeroed by the kernel on first
touch. The export fits (factored and principled models, judged by rendering) are such work:
in the daemon they took twice the CPU they take in a plain process, all of the extra in the
kernel (docs/notes/2026-11-27-export-cpu.md). A fresh interpreter has glibc's own heap
settings, so the fits run there at their plain cost, and everything they allocated goes back
to the system when it exits, which keeps the daemon's size bound as well. Starting it costs
under a second (numpy, scipy and HDR-FLIP imports), against the four or five seconds of CPU
it saves.

A process whose heap is not bounded (``gonio scan``, ``gonio export``, a test calling the fits
directly) runs them where it is: there the fresh interpreter would cost and save nothing.

The fresh interpreter ends with the daemon. A daemon killed while its fits ran (``kill -9``,
the kernel's out-of-memory killer) left it behind for good, a few hundred MB blocked writing
its answer to a pipe nobody reads: it now looks at its parent every
:data:`PARENT_CHECK_S` seconds and exits once that parent is gone.
"""

from __future__ import annotations

import logging
import multiprocessing
import os
import threading
import time
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from typing import Any, TypeVar

from gonio.heap import heap_bounded

log = logging.getLogger("gonio.export")

T = TypeVar("T")

#: How often the fits' process looks whether the daemon that started it is still there, s.
PARENT_CHECK_S = 0.5


def _exit_with_parent(parent_pid: int) -> None:
    """In the fits' process (the pool's initializer): a daemon thread that ends this process
    when its parent ``parent_pid`` is gone (the process is then re-parented, so its parent id
    changes). Nothing is written: the daemon that would read the answer no longer exists, and
    its next start finishes the job again from the stored readings."""

    def watch() -> None:
        while os.getppid() == parent_pid:
            time.sleep(PARENT_CHECK_S)
        os._exit(1)

    threading.Thread(target=watch, name="gonio-parent-watch", daemon=True).start()


def run_fits(fn: Callable[..., T], *args: Any) -> T:
    """``fn(*args)`` in a fresh interpreter when this process's heap is bounded, else here.

    Parameters
    ----------
    fn : a module-level function (it is pickled by name), e.g.
        :func:`gonio.export.fit_all` or :func:`gonio.export.result_fits`
    args : its arguments, picklable (a :class:`~gonio.brdf.tables.table.BRDFTable`, a path)

    Returns
    -------
    What ``fn`` returns. An exception ``fn`` raises is raised here as it is (an
    :class:`~gonio.export.ExportError` keeps its message). When the fresh interpreter cannot
    be started or dies without an answer (killed, out of memory), the fits run here instead,
    and the log says so: the export must not be lost to the way it is computed.
    """
    if not heap_bounded():
        return fn(*args)
    try:
        # spawn, not fork: a fork of this threaded daemon would copy its bounded heap
        # settings and whatever locks its other threads held at that moment.
        with ProcessPoolExecutor(max_workers=1, mp_context=multiprocessing.get_context("spawn"),
                                 initializer=_exit_with_parent,
                                 initargs=(os.getpid(),)) as pool:
            return pool.submit(fn, *args).result()
    except (BrokenProcessPool, OSError) as exc:
        log.warning("the export fits' own process failed (%s); fitting in the daemon, at "
                    "about twice the CPU", exc)
        return fn(*args)
