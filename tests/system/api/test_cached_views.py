"""A finished result's views over HTTP, served from the result views' cache
(gonio/result_cache.py): scans on the simulated rig through a daemon on loopback, their result
files read by the real reader, counted where the cache calls it (``gonio.results.read_result``).

A second request for a view reads nothing and answers the same bytes; a result file rewritten
or rebuilt (``gonio jobs rebuild``'s function, in its own store handle as the command runs) is
read again and served as it is now; the result bound evicts; a damaged or removed file gets
the clear error, never an answer from before.
"""

from __future__ import annotations

import json
import os
import shutil
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import h5py
import httpx
import pytest

import gonio.figures
import gonio.results
from gonio.basis_supply import BasisSupply
from gonio.figures import fit_curves, polar_curves
from gonio.finishing import rebuild_result
from gonio.results import read_result
from gonio.store import JobStore
from tests.system.api.conftest import Daemon, export_fits_off
from tests.system.api.test_scan_flow import scan, wait_state

pytestmark = [pytest.mark.system, pytest.mark.timeout(600)]

POLAR = {"theta_i": 30, "phi_i": 45}


@pytest.fixture(scope="module")
def jobs(daemon: Daemon) -> list[int]:
    """Three completed scans (their fits are not under test)."""
    ids = []
    with export_fits_off(daemon), daemon.client() as c:
        for name in ("cached a", "cached b", "cached c"):
            r = c.post("/api/v1/jobs", json=scan(name, rotations=6))
            assert r.status_code == 201, r.text
            ids.append(r.json()["id"])
        for job_id in ids:
            assert wait_state(c, job_id, {"completed", "failed"}, 300)["state"] == "completed"
    return ids


@pytest.fixture
def reads(monkeypatch: pytest.MonkeyPatch, daemon: Daemon) -> Iterator[list[Path]]:
    """Every result file the daemon's cache reads from disk while the test runs, from an
    empty cache."""
    got: list[Path] = []
    real = gonio.results.read_result

    def counting(path: Any) -> Any:
        got.append(Path(path))
        return real(path)

    service = daemon.app.state.service
    service.results.cache.clear()
    monkeypatch.setattr(gonio.results, "read_result", counting)
    yield got


def _path(daemon: Daemon, job_id: int) -> Path:
    return Path(daemon.app.state.service.result_path(job_id))


def _json(value: Any) -> Any:
    """``value`` as it reads back from JSON (as a client sees it)."""
    return json.loads(json.dumps(value))


def test_a_second_request_reads_nothing_and_answers_the_same(
        daemon: Daemon, jobs: list[int], reads: list[Path],
        monkeypatch: pytest.MonkeyPatch) -> None:
    job = jobs[0]
    computed: list[str] = []
    for name in ("fit_curves", "polar_curves", "render_inputs"):
        real = getattr(gonio.figures, name)

        def counting(*args: Any, _real: Any = real, _name: str = name) -> Any:
            computed.append(_name)
            return _real(*args)

        monkeypatch.setattr(gonio.figures, name, counting)
    base = f"/api/v1/jobs/{job}"
    with daemon.client() as c:
        for path, params in ((f"{base}/fit", {}), (f"{base}/polar", POLAR),
                             (f"{base}/render.png", {}), (f"{base}/preview.png", {})):
            first = c.get(path, params=params)
            assert first.status_code == 200, first.text
            second = c.get(path, params=params)
            assert second.status_code == 200 and second.content == first.content
        fit = c.get(f"{base}/fit").json()
        polar = c.get(f"{base}/polar", params=POLAR).json()
    # One read for all the views, each asked for twice, and each view computed once.
    assert reads == [_path(daemon, job)]
    assert sorted(computed) == ["fit_curves", "polar_curves", "render_inputs"]
    # The same curves as the figures compute from the file read here, uncached.
    res = read_result(_path(daemon, job))
    assert fit == _json(fit_curves(res))
    assert polar == _json(polar_curves(res, POLAR["theta_i"], POLAR["phi_i"]))


def _doubled(path: Path) -> None:
    """Rewrite a result file as gonio writes one (whole, then renamed over it), with its
    samples and its reconstruction twice what they were."""
    part = path.with_suffix(".rewrite")
    shutil.copyfile(path, part)
    with h5py.File(part, "r+") as f:
        for name in ("samples/values", "reconstruction/values"):
            f[name][...] = 2 * f[name][()]
    os.replace(part, path)


def test_a_rewritten_then_rebuilt_result_is_served_as_it_is_now(
        daemon: Daemon, jobs: list[int], reads: list[Path], basis: Any) -> None:
    job = jobs[1]
    path = _path(daemon, job)
    with daemon.client() as c:
        before = c.get(f"/api/v1/jobs/{job}/fit").json()
        polar_before = c.get(f"/api/v1/jobs/{job}/polar", params=POLAR).json()
        _doubled(path)
        after = c.get(f"/api/v1/jobs/{job}/fit").json()
        polar_after = c.get(f"/api/v1/jobs/{job}/polar", params=POLAR).json()
        assert reads == [path, path]
        # Twice the samples; twice the table, so twice its curve (the lookup is cubic in
        # log f: log 2f = log f + log 2).
        for old, new in zip(before["pairs"], after["pairs"], strict=True):
            assert new["measured"] == [None if v is None else 2 * v for v in old["measured"]]
            assert new["curve"] == pytest.approx(
                [None if v is None else 2 * v for v in old["curve"]], rel=1e-6)
        for plane in ("in_plane", "cross_plane"):
            for ch, values in polar_before["reconstruction"][plane].items():
                assert polar_after["reconstruction"][plane][ch] == pytest.approx(
                    [None if v is None else 2 * v for v in values], rel=1e-6)
        assert polar_after["truth"] == polar_before["truth"]  # the truth is not in the table

        # `gonio jobs rebuild`: the file written again from the stored readings.
        summary = rebuild_result(JobStore(daemon.app.state.service.store.path),
                                 daemon.data_dir, job, BasisSupply(lambda: basis))
        assert daemon.data_dir / summary["result_path"] == path
        rebuilt = c.get(f"/api/v1/jobs/{job}/fit").json()
        assert reads == [path, path, path]
        assert rebuilt == _json(fit_curves(read_result(path)))
        for old, new in zip(before["pairs"], rebuilt["pairs"], strict=True):
            assert new["measured"] == pytest.approx(old["measured"], rel=1e-9)


def test_the_result_bound_evicts_the_least_recently_used(
        daemon: Daemon, jobs: list[int], reads: list[Path]) -> None:
    from gonio.result_cache import MAX_RESULTS

    assert MAX_RESULTS == 2 < len(jobs)
    paths = [_path(daemon, j) for j in jobs]
    cell = {"theta_h": 30, "theta_d": 30, "phi_d": 90}
    with daemon.client() as c:
        for job in (*jobs, jobs[2], jobs[0]):
            r = c.get(f"/api/v1/jobs/{job}/slice", params=cell)
            assert r.status_code == 200, r.text
    # a, b, c read; c kept; a evicted by c, so read again.
    assert reads == [paths[0], paths[1], paths[2], paths[0]]
    assert daemon.app.state.service.results.cache.stats().evictions >= 2


def _expect_error(c: httpx.Client, job: int, status: int, words: str) -> None:
    for path, params in (("fit", {}), ("polar", POLAR), ("render.png", {}),
                         ("preview.png", {}), ("slice", {})):
        r = c.get(f"/api/v1/jobs/{job}/{path}", params=params)
        assert r.status_code == status, (path, r.status_code, r.text)
        detail = r.json()["detail"]
        assert words in detail and f"gonio jobs rebuild {job} --db" in detail, detail


def test_a_damaged_or_removed_file_gets_the_clear_error_not_an_old_answer(
        daemon: Daemon, jobs: list[int], reads: list[Path]) -> None:
    job = jobs[2]
    path = _path(daemon, job)
    good = path.read_bytes()
    with daemon.client() as c:
        fit = c.get(f"/api/v1/jobs/{job}/fit")
        assert fit.status_code == 200
        for path_, params in (("polar", POLAR), ("render.png", {}), ("preview.png", {})):
            assert c.get(f"/api/v1/jobs/{job}/{path_}", params=params).status_code == 200
        try:
            # Truncated, as a full disk or a copy cut short leaves it.
            path.write_bytes(good[: len(good) // 2])
            _expect_error(c, job, 500, f"job {job}'s result file is damaged")
            path.unlink()
            _expect_error(c, job, 404, f"job {job}'s result file {path.name} is missing")
        finally:
            path.write_bytes(good)
        again = c.get(f"/api/v1/jobs/{job}/fit")
        assert again.status_code == 200 and again.content == fit.content
