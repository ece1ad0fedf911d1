"""Fixtures shared by every test area."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

PROJECT_ROOT = Path(__file__).resolve().parents[1]

#: Native thread pools each parallel worker (and every process it starts) may use.
WORKER_THREAD_VARS = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS")


def _one_native_thread_per_worker() -> None:
    """Under pytest-xdist, BLAS and OpenMP on one thread in each worker and its children.

    The README's run has one worker more than the cores, and each would otherwise start
    OpenBLAS (and flip-evaluator's OpenMP) threads for every core: more threads than cores,
    whose spin-waiting burns CPU without doing work. Measured on the 2-core machine beside a
    loaded run: the basis, design and posterior tests took 47.8 s of CPU with the default
    threads and 24.1 s with one. Set in the environment (read by those libraries when they
    load, also in the daemons and commands the tests start) and, as numpy may already be
    loaded, through threadpoolctl for this process. A run without ``-n`` keeps the defaults.
    """
    if not os.environ.get("PYTEST_XDIST_WORKER"):
        return
    for name in WORKER_THREAD_VARS:
        os.environ.setdefault(name, "1")
    from threadpoolctl import threadpool_limits

    threadpool_limits(limits=1)


_one_native_thread_per_worker()
SHARED_DATA = PROJECT_ROOT.parent / "shared" / "data"

#: The files that take longest, longest first (wall time of each in a whole parallel run on
#: the quiet machine, its tests' times summed; README "The suite on a busy machine"). The
#: parallel run (``-n auto --dist loadfile``) hands whole files to its workers as they free
#: up; started first, these end before the many short files do, so no worker is left running
#: one of them alone at the end while the others idle. A file missing here only starts later;
#: the list orders the run and decides nothing else.
LONGEST_FIRST = (
    "tests/unit/export/test_judge.py",
    "tests/system/test_readme_session.py",
    "tests/system/api/test_disk_full.py",
    "tests/system/api/test_browser.py",
    "tests/system/test_state_files.py",
    "tests/system/api/test_browser_lab_day.py",
    "tests/system/cli/test_scan_interrupt.py",
    "tests/system/api/test_browser_colour.py",
    "tests/system/api/test_scan_flow.py",
    "tests/unit/brdf/reconstruction/test_shipped.py",
    "tests/system/api/test_start_races.py",
    "tests/system/api/test_colour.py",
    "tests/system/drivers/test_zaber.py",
    "tests/system/api/test_device_wait.py",
    "tests/system/test_durable_state.py",
    "tests/system/test_arc_resume.py",
    "tests/system/test_rebuild.py",
    "tests/unit/test_project.py",
    "tests/unit/cli/test_export_command.py",
    "tests/system/api/test_sim_restart.py",
    "tests/system/api/test_browser_auto_arc.py",
    "tests/system/api/test_fuzz.py",
    "tests/system/test_scan_sim.py",
    "tests/system/cli/test_scan_design_gap.py",
)


def pytest_configure(config: pytest.Config) -> None:
    """Keep :data:`LONGEST_FIRST`'s order in the parallel run: pytest-xdist would otherwise
    sort the files by their number of tests, most first, which sends the long one-test files
    (a whole scan each) last."""
    if hasattr(config.option, "loadscopereorder"):
        config.option.loadscopereorder = False


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """The files of :data:`LONGEST_FIRST` first, in its order; the rest as collected (the
    sort is stable, so a file's tests keep their order and stay together)."""
    rank = {name: k for k, name in enumerate(LONGEST_FIRST)}

    def key(item: pytest.Item) -> int:
        try:
            name = item.path.relative_to(PROJECT_ROOT).as_posix()
        except ValueError:
            return len(rank)
        return rank.get(name, len(rank))

    items.sort(key=key)


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_auto_num_workers(config: pytest.Config) -> int | None:
    """``-n auto``: one worker more than the cores this process may use.

    Most system tests wait part of their time (a simulated stage moving in real time, a daemon
    or browser starting, a device left silent on purpose); one worker per core leaves a core
    idle while its worker waits. ``PYTEST_XDIST_AUTO_NUM_WORKERS`` still decides when set.
    """
    if os.environ.get("PYTEST_XDIST_AUTO_NUM_WORKERS"):
        return None
    return len(os.sched_getaffinity(0)) + 1


def run_wide_dir(tmp_path_factory: pytest.TempPathFactory, name: str) -> Path:
    """A temporary folder ``name`` shared by every process of this test run.

    Under pytest-xdist (the README's ``-n``) each worker has its own base temporary folder,
    ``<run's base>/popen-gw<N>``; a folder in the run's base is seen by all workers, so what is
    built once there (the default basis, the small test basis) is built once per run, not
    once per worker. Writers that share it must write atomically (gonio's ``.npz`` writers
    do), as two workers may build the same file at the same time.
    """
    base = tmp_path_factory.getbasetemp()
    if os.environ.get("PYTEST_XDIST_WORKER"):
        base = base.parent
    path = base / name
    path.mkdir(parents=True, exist_ok=True)
    return path


@pytest.fixture(scope="session", autouse=True)
def _session_cache_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Point gonio's user cache at one temporary folder for the whole run.

    The synthetic library and default basis are built once per test run there (shared by the
    parallel workers: :func:`run_wide_dir`), so tests never read or write the developer's
    real cache.
    """
    if "GONIO_CACHE_DIR" not in os.environ:
        os.environ["GONIO_CACHE_DIR"] = str(run_wide_dir(tmp_path_factory, "gonio-cache"))
    # The user's imported tables (gonio library import) would change the default basis.
    if "GONIO_LIBRARY_DIR" not in os.environ:
        os.environ["GONIO_LIBRARY_DIR"] = str(tmp_path_factory.mktemp("gonio-library"))
    return Path(os.environ["GONIO_CACHE_DIR"])


@pytest.fixture(scope="session", autouse=True)
def _session_data_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Point gonio's user data folder (``gonio scan``, ``gonio serve --sim``) at a temporary one,
    so tests never read or write the developer's jobs and results."""
    if "GONIO_DATA_DIR" not in os.environ:
        os.environ["GONIO_DATA_DIR"] = str(tmp_path_factory.mktemp("gonio-data"))
    return Path(os.environ["GONIO_DATA_DIR"])


@pytest.fixture(autouse=True)
def _test_data_dir(_session_data_dir: Path, tmp_path_factory: pytest.TempPathFactory,
                   monkeypatch: pytest.MonkeyPatch) -> Path:
    """Each test its own user data folder. A rig's data directory there (``gonio scan``'s, and
    the daemon's without a configured one) keeps its calibration, and the simulated rigs of
    different tests share one geometry: one test's white reference must not make another
    test's rig "calibrated" (an uncalibrated scan of a calibrated rig needs acceptance)."""
    path = tmp_path_factory.mktemp("user-data")
    monkeypatch.setenv("GONIO_DATA_DIR", str(path))
    return path


@pytest.fixture(scope="session", autouse=True)
def _session_lock_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Rig ownership locks (gonio.locks) of this test run in one folder of its own.

    Child processes (daemons, CLI commands) inherit it, so they see the test's locks; other
    test runs on the same machine (whose simulators may get the same pseudo-terminal numbers
    once ours are closed) never do.
    """
    if "GONIO_LOCK_DIR" not in os.environ:
        os.environ["GONIO_LOCK_DIR"] = str(tmp_path_factory.mktemp("gonio-locks"))
    return Path(os.environ["GONIO_LOCK_DIR"])


@pytest.fixture(scope="session")
def rgl_dir() -> Path:
    """Folder of the shared RGL measurements; skips the test when it is absent."""
    d = SHARED_DATA / "rgl"
    if not d.is_dir() or not any(d.glob("*.bsdf")):
        pytest.skip(f"shared RGL data not found at ../shared/data/rgl (looked in {d})")
    return d
