"""BLAS on one thread: for every ``gonio`` command, and around reconstruction's linear algebra.

The reconstruction's products and factorisations are a few MFLOP each. With OpenBLAS' default
threads on a shared 2-core machine, the threads' spin-waiting made a 0.7 ms solve take 65 ms
(docs/science.md 2), so every solve of the joint fit, its posterior and V&F's path runs inside
:func:`one_blas_thread`, whoever calls it.

The larger products gain nothing from a second thread either. On the idle 2-core machine, a
thread per core against one (whole processes, medians of 4-5 runs, one run for the basis):
``gonio design`` with a warm cache 5.4 against 4.1 s of CPU in the same wall time; the default
basis' fold-in 0.86 against 0.65 s of CPU, 0.62 against 0.65 s of wall; the basis build of
``bench/bench_basis.py`` 15.4 against 9.8 s of CPU and 12.6 against 9.8 s of wall. So every
``gonio`` command runs BLAS on one thread (:func:`prefer_one_thread`) unless the user set the
number of threads.
"""

from __future__ import annotations

import contextlib
import functools
import os
import sys
from collections.abc import Iterator
from typing import Any

#: Variables OpenBLAS reads for its number of threads, in its order of precedence.
THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "GOTO_NUM_THREADS", "OMP_NUM_THREADS")


def prefer_one_thread() -> bool:
    """Run this process' BLAS on one thread, unless the user set the number of threads.

    Sets ``OPENBLAS_NUM_THREADS=1`` in the environment, which each OpenBLAS reads when it
    loads (NumPy's, and SciPy's own when SciPy loads later); one already loaded is limited
    through threadpoolctl. Called first by the ``gonio`` command line.

    Returns
    -------
    bool
        False, changing nothing, when one of :data:`THREAD_VARIABLES` is set.
    """
    if any(name in os.environ for name in THREAD_VARIABLES):
        return False
    os.environ["OPENBLAS_NUM_THREADS"] = "1"
    if "numpy" in sys.modules or "scipy" in sys.modules:
        from threadpoolctl import threadpool_limits

        threadpool_limits(limits=1, user_api="blas")
    return True


@functools.cache
def _blas_controller() -> Any:
    """The process' threadpoolctl controller (scanning the loaded libraries takes ~10 ms).

    It controls only the libraries loaded when it is made, and SciPy's LAPACK (the SVDs of
    ``least_squares``, ``scipy.linalg``) is an OpenBLAS of its own beside NumPy's: it is loaded
    first, else a first call before anything imported ``scipy.linalg`` (``gonio export`` in a
    fresh process) left SciPy's two threads spinning for the rest of the process (the export's
    rendered fit spent about a quarter of its CPU in them).
    """
    import scipy.linalg  # noqa: F401  (loads SciPy's BLAS, so that the scan below sees it)
    from threadpoolctl import ThreadpoolController

    return ThreadpoolController()


@contextlib.contextmanager
def one_blas_thread() -> Iterator[None]:
    """Run the block with BLAS limited to one thread.

    Reconstruction's products are a few MFLOP; with several OpenBLAS threads on a shared
    2-core machine the threads' spin-waiting made a 0.7 ms solve take 65 ms. The limit is
    process-wide while the block runs (threadpoolctl sets the library's global thread count).
    """
    with _blas_controller().limit(limits=1, user_api="blas"):
        yield
