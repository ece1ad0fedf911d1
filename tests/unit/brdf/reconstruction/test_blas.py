"""Reconstruction's linear algebra runs with BLAS on one thread, and only inside the block."""

from __future__ import annotations

import json

import numpy  # noqa: F401  (the BLAS libraries reconstruction uses, loaded as it loads them)
import pytest
import scipy.linalg  # noqa: F401
from threadpoolctl import threadpool_info, threadpool_limits

from gonio.brdf.reconstruction.blas import THREAD_VARIABLES, one_blas_thread


def _blas_threads() -> list[int]:
    return [int(p["num_threads"]) for p in threadpool_info() if p["user_api"] == "blas"]


def test_blas_runs_on_one_thread_inside_the_block_only() -> None:
    # Two threads outside, as the libraries' default on two cores (a parallel test worker runs
    # on one, tests/conftest.py), so that the block's limit and its lifting are both seen.
    with threadpool_limits(limits=2, user_api="blas"):
        before = _blas_threads()
        if not before:
            pytest.skip("no BLAS library loaded that threadpoolctl can control")
        assert before == [2] * len(before)
        with one_blas_thread():
            assert _blas_threads() == [1] * len(before)
        assert _blas_threads() == before


def test_the_limit_is_lifted_when_the_block_raises() -> None:
    with threadpool_limits(limits=2, user_api="blas"):
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


_BLAS_OF_THE_PROCESS = (
    "def blas():\n"
    "    from threadpoolctl import threadpool_info\n"
    "    return sorted((p['filepath'], p['num_threads']) for p in threadpool_info()\n"
    "                  if p['user_api'] == 'blas')\n"
)


def _run(code: str, **env: str) -> dict[str, object]:
    import os
    import subprocess
    import sys

    base = {k: v for k, v in os.environ.items() if k not in THREAD_VARIABLES}
    out = subprocess.run([sys.executable, "-c", code], env={**base, **env},
                         capture_output=True, text=True, check=True, timeout=120)
    return dict(json.loads(out.stdout.splitlines()[-1]))


def test_a_gonio_command_runs_numpys_and_scipys_blas_on_one_thread(tmp_path: object) -> None:
    """``gonio.cli.main`` limits the process before it loads NumPy; SciPy's OpenBLAS, loaded
    later, reads the same limit. Against the libraries' own default in the same interpreter."""
    code = (
        "import json, sys\n" + _BLAS_OF_THE_PROCESS
        + "import numpy, scipy.linalg\n"
        "default = blas()\n"
        "print(json.dumps({'default': default}))\n"
    )
    default = _run(code)["default"]
    assert isinstance(default, list)
    if not any(n > 1 for _, n in default):
        pytest.skip("no BLAS library that threadpoolctl controls runs on more than one thread")
    code = (
        "import json, os, sys\n" + _BLAS_OF_THE_PROCESS
        + "from gonio.cli import main\n"
        "assert 'numpy' not in sys.modules\n"
        "main(['jobs', 'list', '--db', sys.argv[1]])  # any command: its exit code aside\n"
        "import scipy.linalg\n"
        "print(json.dumps({'numpy': 'numpy' in sys.modules, 'blas': blas(),\n"
        "                  'env': os.environ.get('OPENBLAS_NUM_THREADS')}))\n"
    )
    import subprocess
    import sys

    base = {k: v for k, v in __import__("os").environ.items() if k not in THREAD_VARIABLES}
    out = subprocess.run([sys.executable, "-c", code, f"{tmp_path}/gonio.sqlite"], env=base,
                         capture_output=True, text=True, check=True, timeout=120)
    got = json.loads(out.stdout.splitlines()[-1])
    assert got["numpy"] is True and got["env"] == "1"
    assert any("scipy" in path for path, _ in got["blas"])
    assert [n for _, n in got["blas"]] == [1] * len(got["blas"])


def test_a_thread_count_the_user_set_is_kept() -> None:
    code = (
        "import json\n" + _BLAS_OF_THE_PROCESS
        + "from gonio.brdf.reconstruction.blas import prefer_one_thread\n"
        "import numpy\n"
        "changed = prefer_one_thread()\n"
        "print(json.dumps({'changed': changed, 'blas': blas()}))\n"
    )
    got = _run(code, OPENBLAS_NUM_THREADS="2")
    assert got["changed"] is False
    assert [n for _, n in got["blas"]] == [2] * len(got["blas"])  # type: ignore[arg-type]
    # Without the user's setting, NumPy's BLAS, already loaded, is limited through threadpoolctl.
    got = _run(code)
    assert got["changed"] is True
    assert [n for _, n in got["blas"]] == [1] * len(got["blas"])  # type: ignore[arg-type]
