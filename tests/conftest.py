"""Fixtures shared by every test area."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

PROJECT_ROOT = Path(__file__).resolve().parents[1]
SHARED_DATA = PROJECT_ROOT.parent / "shared" / "data"


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
