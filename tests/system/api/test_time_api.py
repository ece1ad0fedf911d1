"""Dry runs over HTTP: the cap on stage angles is a clear 422, adaptive plans get a bound,
and the estimate says where the stage starts; plot endpoints refuse what they cannot draw."""

from __future__ import annotations

import time

import pytest

from gonio.plans.models import MAX_ROTATIONS
from tests.system.api.conftest import Daemon

pytestmark = pytest.mark.system


def test_dry_run_cap_bound_and_start(daemon: Daemon, no_export_fits: None) -> None:
    with daemon.client() as c:
        r = c.post("/api/v1/jobs/dry-run", json={"plan": {"kind": "uniform",
                                                          "rotations": MAX_ROTATIONS + 1}})
        assert r.status_code == 422
        assert f"at most {MAX_ROTATIONS} stage angles" in r.json()["detail"]
        r = c.post("/api/v1/jobs", json={"plan": {"kind": "uniform",
                                                  "rotations": MAX_ROTATIONS + 1}})
        assert r.status_code == 422 and "at most" in r.json()["detail"]
        d = c.post("/api/v1/jobs/dry-run", json={"plan": {"kind": "adaptive"}}).json()
        assert d["max_estimated_s"] > d["estimated_s"] > 0 and d["max_angles"] > 8
        assert d["from_known"] is False and d["from_deg"] == 0.0
        # Once a job has measured, the daemon knows where it left the stage and times from there.
        job = c.post("/api/v1/jobs", json={"plan": {
            "kind": "uniform", "rotations": 2, "start_deg": 100,
            "exposure": {"exposure_s": 0.005}}}).json()["id"]
        deadline = time.monotonic() + 120
        while c.get(f"/api/v1/jobs/{job}").json()["state"] not in ("completed", "failed"):
            assert time.monotonic() < deadline
            time.sleep(0.2)
        last = c.get(f"/api/v1/jobs/{job}/readings").json()[-1]["actual_deg"]
        d = c.post("/api/v1/jobs/dry-run", json={"plan": {"kind": "uniform"}}).json()
        assert d["from_known"] is True and d["from_deg"] == pytest.approx(last)


def test_plot_endpoints_need_a_reconstruction(daemon: Daemon) -> None:
    with daemon.client() as c:
        for path in ("render.png", "fit", "polar"):
            r = c.get(f"/api/v1/jobs/999/{path}")
            assert r.status_code == 404 and "no job with id 999" in r.json()["detail"]
        r = c.get("/api/v1/jobs/1/polar?theta_i=95")
        assert r.status_code == 422
