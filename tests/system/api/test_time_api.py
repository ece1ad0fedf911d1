"""Dry runs over HTTP: the cap on stage angles is a clear 422, adaptive plans get a bound,
the estimate says where the stage starts, and the layout's distance from the mirror direction
is given before the scan and in its result; plot endpoints refuse what they cannot draw."""

from __future__ import annotations

import time

import numpy as np
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
        # The layout's mirror gap, before the scan and in the result: the least tilt of a
        # pair's half vector (l + s) / |l + s| from the normal (z).
        gap = min(float(np.degrees(np.arccos((p.wi + p.wo)[2] / np.linalg.norm(p.wi + p.wo))))
                  for p in daemon.sim.config.pair_directions())
        assert gap > 1.0  # the default simulated rig has no pair at the mirror direction
        assert d["mirror_gap_deg"] == pytest.approx(gap, abs=1e-6)
        assert f"within {gap:.1f} degrees of the specimen normal" in d["mirror_gap"]
        assert not any("mirror" in w for w in d["warnings"])  # a note, not a warning
        m = c.get(f"/api/v1/jobs/{job}/metrics").json()
        assert m["mirror_gap_deg"] == pytest.approx(gap, abs=1e-6)
        assert m["mirror_gap"] == d["mirror_gap"]
        # The whole note, or the gap alone after a highlight-not-read warning that already
        # says to read a pair near the mirror direction.
        said = m["headline_error"]["meaning"].rsplit(" Note: ", 1)[1]
        assert said == f"{d['mirror_gap']}." or (
            "highlight_not_read" in m and d["mirror_gap"].startswith(said[:-1]))
        cal = c.post("/api/v1/jobs/dry-run", json={"plan": {
            "kind": "calibration", "reference_albedo": 0.99, "rotations": 2}}).json()
        assert cal["mirror_gap_deg"] is None and cal["mirror_gap"] is None


def test_plot_endpoints_need_a_reconstruction(daemon: Daemon) -> None:
    with daemon.client() as c:
        for path in ("render.png", "fit", "polar"):
            r = c.get(f"/api/v1/jobs/999/{path}")
            assert r.status_code == 404 and "no job with id 999" in r.json()["detail"]
        r = c.get("/api/v1/jobs/1/polar?theta_i=95")
        assert r.status_code == 422
