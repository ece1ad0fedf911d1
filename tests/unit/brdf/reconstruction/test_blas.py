"""Reconstruction's linear algebra runs with BLAS on one thread, and only inside the block."""

from __future__ import annotations

import json

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


def test_scipys_blas_is_limited_when_the_first_block_runs_before_scipy_is_imported() -> None:
    """SciPy's LAPACK (``least_squares``' SVDs) is an OpenBLAS of its own beside NumPy's. In a
    fresh process whose first block runs before anything imported ``scipy.linalg`` (``gonio
    export``), that library is limited too."""
    import os
    import subprocess
    import sys

    code = (
        "import json, numpy\n"
        "from threadpoolctl import threadpool_info\n"
        "from gonio.brdf.reconstruction.blas import one_blas_thread\n"
        "def blas():\n"
        "    return sorted((p['filepath'], p['num_threads']) for p in threadpool_info()\n"
        "                  if p['user_api'] == 'blas')\n"
        "with one_blas_thread():\n"
        "    import scipy.linalg\n"
        "    inside = blas()\n"
        "print(json.dumps({'inside': inside, 'after': blas()}))\n"
    )
    env = {k: v for k, v in os.environ.items()
           if k not in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS")}  # the libraries' defaults
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True,
                         check=True, timeout=120)
    got = json.loads(out.stdout)
    if not any(n > 1 for _, n in got["after"]):
        pytest.skip("no BLAS library that threadpoolctl controls runs on more than one thread")
    assert any("scipy" in path for path, _ in got["inside"])
    assert [n for _, n in got["inside"]] == [1] * len(got["after"])
