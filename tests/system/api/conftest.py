"""A running gonio daemon on a simulated rig, shared by the API tests of one module.

The daemon is the real thing end to end: the simulated rig speaks the real wire protocols, the
real drivers talk to it, the service runs the engine, and uvicorn serves the app on loopback.
Only the reconstruction basis is small (a few library materials, K = 8), so building it takes
seconds instead of the minutes the default basis needs; it is cached in the session's cache dir.
"""

from __future__ import annotations

import os
import secrets
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import httpx
import pytest

from gonio.api.auth import ApiKeyring
from gonio.basis_supply import BasisSupply
from gonio.daemon import DaemonConfig, build_app
from tests.system.api.live_server import live_server

SMALL_K = 8
N_MATERIALS = 6
DESIGN_LIMIT_S = 5.0


def small_basis() -> Any:
    """A K=8 basis from 6 library materials, built once per test session (cached on disk)."""
    from gonio.brdf.materials.library import library_specs
    from gonio.brdf.models import analytic as bm
    from gonio.brdf.reconstruction.basis import Basis, build_basis

    path = Path(os.environ["GONIO_CACHE_DIR"]) / f"api-test-basis-K{SMALL_K}.npz"
    if path.is_file():
        return Basis.load(path)
    specs = library_specs()
    picked = specs[:: len(specs) // N_MATERIALS][:N_MATERIALS]
    basis = build_basis([bm.tabulate(s.model) for s in picked], SMALL_K)
    basis.save(path)
    return basis


@dataclass
class Daemon:
    url: str
    key: str
    app: Any
    sim: Any
    data_dir: Path

    def client(self, key: str | None = "default") -> httpx.Client:
        headers = {} if key is None else {"X-API-Key": self.key if key == "default" else key}
        return httpx.Client(base_url=self.url, headers=headers, timeout=30)


@pytest.fixture(scope="session")
def basis() -> Any:
    return small_basis()


@pytest.fixture(scope="module")
def daemon(tmp_path_factory: pytest.TempPathFactory, basis: Any) -> Iterator[Daemon]:
    from gonio.sim.rig import SimRigOptions, start_sim_rig

    data_dir = tmp_path_factory.mktemp("gonio-data")
    # Fast stage physics and short settle times keep a full 8-angle scan to a few seconds.
    sim = start_sim_rig(SimRigOptions(time_scale=10.0, settle_s=0.0))
    key = secrets.token_hex(24)  # a key starting with '-' reads as an option on a CLI
    # A short design limit keeps design requests (tests and fuzzing) to a few seconds each.
    cfg = DaemonConfig().with_overrides(paths__data_dir=str(data_dir),
                                        limits__design_time_limit_s=DESIGN_LIMIT_S)
    app = build_app(cfg, sim.config, ApiKeyring({"tester": key}), basis=BasisSupply(lambda: basis))
    from gonio.figures import describe_material

    # As `gonio serve --sim` does: results record the simulated material (the truth).
    app.state.service.specimen_truth = lambda: describe_material(sim.specimen.brdf)
    try:
        with live_server(app) as url:
            yield Daemon(url, key, app, sim, data_dir)
    finally:
        sim.close()


@contextmanager
def export_fits_off(daemon: Daemon) -> Iterator[None]:
    """While in the block, ``daemon``'s scans finish without the export fits
    (``Worker.fit_exports``, the factored and principled fits stored in each result, with
    their rendered check: several seconds of CPU per scan, far more than a short scan's
    reconstruction). For the scans of a test that asserts nothing about their fits."""
    worker = daemon.app.state.service.worker
    before = worker.fit_exports
    worker.fit_exports = False
    try:
        yield
    finally:
        worker.fit_exports = before


@pytest.fixture
def no_export_fits(daemon: Daemon) -> Iterator[None]:
    """For a test none of whose assertions looks at the export fits: while it runs, the shared
    daemon's scans finish without them (:func:`export_fits_off`). The daemon's default stays on
    for every other test; the stored fits are asserted by test_scan_flow's full scan."""
    with export_fits_off(daemon):
        yield


@pytest.fixture(scope="module")
def odd_daemon(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Daemon]:
    """A daemon of its own with the default basis provider, whose built default basis (in a
    cache folder of its own: the session's must not get it) has an odd harmonic in its prior:
    a material without twofold symmetry, ``pile-lean``, as a lab's import would bring."""
    from gonio.brdf.reconstruction.basis import Basis, default_basis_path
    from tests.unit.brdf.reconstruction.test_reconstruct import random_basis
    from tests.unit.brdf.reconstruction.test_reconstruct_joint import _with_prior

    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("GONIO_CACHE_DIR", str(tmp_path_factory.mktemp("odd-cache")))
        b = _with_prior(random_basis(6, seed=1), {0: 1.0, 1: 0.3, 2: 0.5})
        odd = Basis(b.Q, b.S, b.f_med, b.mu, b.valid, b.eps, b.materials,
                    {"without_twofold_symmetry": ["pile-lean"]}, b.ph_prior)
        path = default_basis_path()
        path.parent.mkdir(parents=True, exist_ok=True)
        odd.save(path)
        yield from _own_daemon(tmp_path_factory)


SLOW_BASIS_S = 9.0
"""How long :func:`slow_basis_daemon`'s basis takes to load: longer than the 6 s finishing
estimate a daemon without a finished scan gives (gonio.timeleft.FINISHING_FALLBACK_S)."""


@pytest.fixture(scope="module")
def slow_basis_daemon(tmp_path_factory: pytest.TempPathFactory, basis: Any) -> Iterator[Daemon]:
    """A daemon of its own whose first basis load takes :data:`SLOW_BASIS_S` (as a first
    scan's fold-in on a busy machine), without export fits and with no scan finished yet: a
    finishing that runs past its estimate."""
    import time

    def slow() -> Any:
        time.sleep(SLOW_BASIS_S)
        return basis

    yield from _own_daemon(tmp_path_factory, BasisSupply(slow))


def _own_daemon(tmp_path_factory: pytest.TempPathFactory,
                basis: BasisSupply | None = None) -> Iterator[Daemon]:
    """A daemon of its own on a simulated rig and a fresh data directory, without export fits
    (the results are not under test), with ``basis`` (None: the default provider)."""
    from gonio.sim.rig import SimRigOptions, start_sim_rig

    data_dir = tmp_path_factory.mktemp("gonio-data")
    sim = start_sim_rig(SimRigOptions(time_scale=10.0, settle_s=0.0))
    key = secrets.token_hex(24)
    cfg = DaemonConfig().with_overrides(paths__data_dir=str(data_dir))
    app = build_app(cfg, sim.config, ApiKeyring({"tester": key}), basis=basis)
    app.state.service.worker.fit_exports = False
    try:
        with live_server(app) as url:
            yield Daemon(url, key, app, sim, data_dir)
    finally:
        sim.close()
