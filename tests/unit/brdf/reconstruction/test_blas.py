"""Reconstruction's linear algebra runs with BLAS on one thread, and only inside the block."""

from __future__ import annotations

import numpy  # noqa: F401  (the BLAS libraries reconstruction uses, loaded as it loads them)
import pytest
import scipy.linalg  # noqa: F401
from threadpoolctl import threadpool_info

from gonio.brdf.reconstruction.blas import one_blas_thread


def _blas_threads() -> list[int]:
    return [int(p["num_threads"]) for p in threadpool_info() if p["user_api"] == "blas"]


def test_blas_runs_on_one_thread_inside_the_block_only() -> None:
    before = _blas_threads()
    if not before:
        pytest.skip("no BLAS library loaded that threadpoolctl can control")
    with one_blas_thread():
        assert _blas_threads() == [1] * len(before)
    assert _blas_threads() == before


def test_the_limit_is_lifted_when_the_block_raises() -> None:
    before = _blas_threads()
    with pytest.raises(ZeroDivisionError), one_blas_thread():
        _ = 1 / 0
    assert _blas_threads() == before
