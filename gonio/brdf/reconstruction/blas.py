"""BLAS on one thread around reconstruction's small linear algebra.

The reconstruction's products and factorisations are a few MFLOP each. With OpenBLAS' default
threads on a shared 2-core machine, the threads' spin-waiting made a 0.7 ms solve take 65 ms
(docs/science.md 2), so every solve of the joint fit, its posterior and V&F's path runs inside
:func:`one_blas_thread`.
"""

from __future__ import annotations

import contextlib
import functools
from collections.abc import Iterator
from typing import Any


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
