"""A full scan through the REST API of a daemon on a simulated rig, watched over SSE."""

from __future__ import annotations

import json
import time
from typing import Any

import h5py
import httpx
import pytest

from tests.system.api.conftest import Daemon
from tests.system.api.sse import EventCollector

pytestmark = pytest.mark.system

ROTATIONS = 8
FAST = {"exposure_s": 0.005, "averages": 1, "light_settle_s": 0.0}


def scan(specimen: str, rotations: int = ROTATIONS, **extra: Any) -> dict[str, Any]:
    return {"plan": {"kind": "uniform", "specimen": specimen, "rotations": rotations,
                     "exposure": FAST, **extra}}


#: The states a job ends in (what a test waits for after it aborts or lets a job run out).
ENDED = {"completed", "failed", "aborted"}


def wait_state(
    c: httpx.Client, job_id: int, states: set[str], timeout: float = 120
) -> dict[str, Any]:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        job = c.get(f"/api/v1/jobs/{job_id}").json()
        if job["state"] in states:
            return job
        time.sleep(0.1)
    raise TimeoutError(f"job {job_id} still {job['state']} after {timeout} s (wanted {states})")


def test_health_rig_and_page(daemon: Daemon) -> None:
    with daemon.client(key=None) as c:
        h = c.get("/health").json()
        assert h["status"] == "ok" and h["seq"] >= 0
        rig = c.get("/api/v1/rig").json()
        assert rig["name"] == daemon.sim.config.rig.name
        n_pairs = len(daemon.sim.config.pair_list())
        assert len(rig["description"]["pairs"]) == n_pairs
        assert c.get("/api/v1/rig/config").json()["stage"]["driver"] == "dynamixel"
        page = c.get("/")
        assert page.status_code == 200 and 'src="/static/app.js"' in page.text
        assert c.get("/static/app.js").status_code == 200
        assert "gonio_jobs{state=\"queued\"}" in c.get("/metrics").text


def test_full_scan_with_live_progress_and_results(daemon: Daemon) -> None:
    n_pairs = len(daemon.sim.config.pair_list())
    with daemon.client() as c:
        seq0 = c.get("/health").json()["seq"]
        events = EventCollector(daemon.url, since=seq0)
        try:
            assert events.connected.wait(10)
            r = c.post("/api/v1/jobs", json=scan("brushed sample"))
            assert r.status_code == 201, r.text
            job_id = r.json()["id"]
            assert r.headers["location"] == f"/api/v1/jobs/{job_id}"
            done = events.wait_for(lambda e: e["job_id"] == job_id and e["type"] == "state"
                                   and e["data"]["state"] in ("completed", "failed"), timeout=180)
            assert done["data"]["state"] == "completed", done
            got = [e for e in events.snapshot() if e["job_id"] == job_id]
        finally:
            events.close()
        # Progress arrived angle by angle, in order, with no seq lost or repeated.
        progress = [e["data"]["done"] for e in got if e["type"] == "progress"]
        assert progress == list(range(1, ROTATIONS + 1))
        seqs = [e["seq"] for e in events.snapshot()]
        assert seqs == sorted(set(seqs)) and seqs[0] == seq0 + 1
        assert seqs == list(range(seqs[0], seqs[-1] + 1))

        job = c.get(f"/api/v1/jobs/{job_id}").json()
        assert job["state"] == "completed"
        assert job["done_angles"] == job["total_angles"] == ROTATIONS
        assert job["plan"]["specimen"] == "brushed sample"
        readings = c.get(f"/api/v1/jobs/{job_id}/readings").json()
        assert len(readings) == ROTATIONS * n_pairs
        assert all(0 <= r["specimen_deg"] < 360 for r in readings)

        metrics = c.get(f"/api/v1/jobs/{job_id}/metrics").json()
        assert metrics["n_samples"] == ROTATIONS * n_pairs
        assert 0 <= metrics["rel_sample_error"] < 10

        png = c.get(f"/api/v1/jobs/{job_id}/preview.png")
        assert png.headers["content-type"] == "image/png"
        assert png.content.startswith(b"\x89PNG\r\n\x1a\n")

        cell = {"theta_h": 30, "theta_d": 30, "phi_d": 90}
        sl = c.get(f"/api/v1/jobs/{job_id}/slice", params=cell).json()
        assert len(sl["phi_h_deg"]) == 72
        assert set(sl["values"]) == set(daemon.sim.config.sensors[0].channels)
        off = c.get(f"/api/v1/jobs/{job_id}/slice", params={"theta_h": 31})
        assert off.status_code == 422
        assert "theta_h = 31 deg is not on the 5 degree grid" in off.json()["detail"]

        h5 = c.get(f"/api/v1/jobs/{job_id}/result")
        assert h5.status_code == 200
        assert h5.content.startswith(b"\x89HDF\r\n\x1a\n")
        assert f"gonio-job-{job_id}-brushed-sample.h5" in h5.headers["content-disposition"]
        path = daemon.data_dir / "downloaded.h5"
        path.write_bytes(h5.content)
        with h5py.File(path) as f:
            assert f["reconstruction/values"].shape[1:] == (72, 18, 18, 36)
            assert f["factored/D"].shape == (18, 72) and "params" in f["principled"].attrs

        # Exports through the service layer, from the fits the worker stored.
        gl = c.get(f"/api/v1/jobs/{job_id}/export", params={"format": "gltf"})
        assert gl.status_code == 200, gl.text
        doc = gl.json()
        assert doc["asset"]["version"] == "2.0" and doc["asset"]["extras"]["job_id"] == job_id
        # What the file is (issue 26): a simulated rig's scan says so, with the headline
        # self-estimate the daemon stored and the fit's rendered difference.
        extras = doc["asset"]["extras"]
        assert extras["source"] == "simulated" and extras["simulated_material"]
        assert extras["reconstruction_error"]["predicted_log_rmse"] == pytest.approx(
            c.get(f"/api/v1/jobs/{job_id}").json()["result"]["predicted_log_rmse"])
        assert extras["fits"]["principled"]["rendered"]["value"] >= 0
        assert f"gonio-job-{job_id}-brushed-sample-gltf.gltf" in gl.headers["content-disposition"]
        mt = c.get(f"/api/v1/jobs/{job_id}/export", params={"format": "mtlx"})
        assert mt.status_code == 200 and b"standard_surface" in mt.content
        bad = c.get(f"/api/v1/jobs/{job_id}/export", params={"format": "obj"})
        assert bad.status_code == 422 and "factored" in bad.text
        # A glTF that opens anywhere (issue 26 item 4): the preview sphere, with tangents,
        # on request; the plain export above has no mesh.
        assert "meshes" not in doc
        meshed = c.get(f"/api/v1/jobs/{job_id}/export",
                       params={"format": "gltf", "with_mesh": "true"})
        assert meshed.status_code == 200, meshed.text
        (prim,) = meshed.json()["meshes"][0]["primitives"]
        assert {"POSITION", "NORMAL", "TANGENT"} <= set(prim["attributes"])
        assert (f"gonio-job-{job_id}-brushed-sample-gltf-mesh.gltf"
                in meshed.headers["content-disposition"])
        wrong = c.get(f"/api/v1/jobs/{job_id}/export",
                      params={"format": "mtlx", "with_mesh": "true"})
        assert wrong.status_code == 422 and "gltf or glb only" in wrong.json()["detail"]
        # The binary glTF (GLB 2.0 container): its media type, its name, the header's magic
        # and the same material as the .gltf.
        glb = c.get(f"/api/v1/jobs/{job_id}/export",
                    params={"format": "glb", "with_mesh": "true"})
        assert glb.status_code == 200, glb.text
        assert glb.headers["content-type"] == "model/gltf-binary"
        assert (f"gonio-job-{job_id}-brushed-sample-glb-mesh.glb"
                in glb.headers["content-disposition"])
        assert glb.content[:4] == b"glTF" and int.from_bytes(glb.content[8:12], "little") == len(
            glb.content)
        size = int.from_bytes(glb.content[12:16], "little")
        assert glb.content[16:20] == b"JSON"
        assert json.loads(glb.content[20:20 + size])["materials"] == doc["materials"]
        # A download says what `gonio export` prints as warnings, in a header: the MERL file
        # of this anisotropic specimen holds only its azimuthal average, asked for once and
        # again from the kept file.
        assert json.loads(gl.headers["x-gonio-export-warnings"]) == extras["warnings"]
        for _ in range(2):
            merl = c.get(f"/api/v1/jobs/{job_id}/export", params={"format": "merl"})
            assert merl.status_code == 200, merl.text
            warned = json.loads(merl.headers["x-gonio-export-warnings"])
            assert any("azimuthal average" in w and "gltf, glb, mtlx or table" in w
                       for w in warned), warned
        # Its provenance sidecar, which stayed on the daemon's disk, is downloadable, named
        # as gonio export names it beside the file; only MERL has one.
        side = c.get(f"/api/v1/jobs/{job_id}/export", params={"format": "merl",
                                                              "part": "sidecar"})
        assert side.status_code == 200, side.text
        assert (f"gonio-job-{job_id}-brushed-sample-merl.binary.json"
                in side.headers["content-disposition"])
        record = side.json()
        assert record["job_id"] == job_id and record["merl"]["azimuthally_averaged"] is True
        assert record["warnings"] == warned
        wrong = c.get(f"/api/v1/jobs/{job_id}/export", params={"format": "gltf",
                                                               "part": "sidecar"})
        assert wrong.status_code == 422 and "merl only" in wrong.json()["detail"]


def test_sse_resync_replays_missed_events(daemon: Daemon, no_export_fits: None) -> None:
    """A client that reconnects with Last-Event-ID gets exactly the events after it."""
    with daemon.client() as c:
        r = c.post("/api/v1/jobs", json=scan("resync", rotations=4))
        job_id = r.json()["id"]
        wait_state(c, job_id, {"completed", "failed"})
        mine = c.get(f"/api/v1/jobs/{job_id}").json()
        assert mine["state"] == "completed"
    seq_now = httpx.get(f"{daemon.url}/health").json()["seq"]
    replay = EventCollector(daemon.url, headers={"Last-Event-ID": str(seq_now - 5)})
    try:
        replay.wait_for(lambda e: e["seq"] == seq_now, timeout=20)
        assert [e["seq"] for e in replay.snapshot()][:5] == list(range(seq_now - 4, seq_now + 1))
    finally:
        replay.close()


def test_controls_pause_resume_cancel_reorder_remove(daemon: Daemon,
                                                     no_export_fits: None) -> None:
    with daemon.client() as c:
        first = c.post("/api/v1/jobs", json=scan("long", rotations=36)).json()["id"]
        second = c.post("/api/v1/jobs", json=scan("queued-2", rotations=4)).json()["id"]
        third = c.post("/api/v1/jobs", json=scan("queued-3", rotations=4)).json()["id"]
        wait_state(c, first, {"running"})

        # Queue order: move the third job in front of the second.
        r = c.post(f"/api/v1/jobs/{third}/reorder", json={"position": 0})
        assert r.status_code == 200, r.text
        assert c.get(f"/api/v1/jobs/{third}").json()["queue_position"] == 0
        assert c.get(f"/api/v1/jobs/{second}").json()["queue_position"] == 1

        r = c.post(f"/api/v1/jobs/{first}/pause")
        assert r.status_code == 200, r.text
        paused = wait_state(c, first, {"paused"})
        done_at_pause = paused["done_angles"]
        time.sleep(0.5)
        assert c.get(f"/api/v1/jobs/{first}").json()["done_angles"] == done_at_pause
        # A paused job cannot be paused again, and a running one cannot be resumed.
        assert c.post(f"/api/v1/jobs/{first}/pause").status_code in (409,)
        resumed = c.post(f"/api/v1/jobs/{first}/resume")
        assert resumed.status_code == 200
        # The answer is the job once its engine took the request (it read "paused", and a
        # script checking it concluded the resume had failed); within the answer's wait it
        # is running, or done already, never still paused.
        assert resumed.json()["state"] in ("running", "reconstructing", "completed"), resumed.text
        wait_state(c, first, {"running", "completed"})

        # Cancel works only while queued; remove only when queued or finished.
        assert c.post(f"/api/v1/jobs/{second}/cancel").json()["state"] == "aborted"
        r = c.post(f"/api/v1/jobs/{second}/cancel")
        assert r.status_code == 409 and "queued" in r.json()["detail"]
        r = c.delete(f"/api/v1/jobs/{first}")
        assert r.status_code == 409
        assert c.post(f"/api/v1/jobs/{first}/abort").status_code == 200
        wait_state(c, first, {"aborted"})
        assert c.delete(f"/api/v1/jobs/{second}").status_code == 204
        assert c.get(f"/api/v1/jobs/{second}").status_code == 404
        wait_state(c, third, {"completed"})


def test_user_errors_get_clear_statuses(daemon: Daemon) -> None:
    with daemon.client() as c:
        r = c.post("/api/v1/jobs", json=scan("bad", rotations=0))
        assert r.status_code == 422 and "rotations" in r.text
        bad_pair = {"kind": "uniform", "pairs": [{"light": "L9", "sensor": "S1"}]}
        r = c.post("/api/v1/jobs", json={"plan": bad_pair})
        assert r.status_code == 422 and "L9" in r.json()["detail"]
        r = c.post("/api/v1/jobs", json={"plan": {"kind": "spiral"}})
        assert r.status_code == 422
        assert c.get("/api/v1/jobs/999999").status_code == 404
        assert c.post("/api/v1/jobs/999999/pause").status_code == 404
        dry = c.post("/api/v1/jobs/dry-run", json=scan("dry"))
        assert dry.status_code == 200 and dry.json()["readings"] > 0
        # A job without a result yet: 404 with a reason, not a 500. The queue is held, so it
        # stays queued until cancelled (started, it would measure and fit in the background
        # long after this test).
        assert c.post("/api/v1/rig/halt").status_code == 200
        try:
            q = c.post("/api/v1/jobs", json=scan("pending", rotations=4)).json()["id"]
            assert c.post(f"/api/v1/jobs/{q}/cancel").json()["state"] == "aborted"
            # Cancelled, it will never have one: said so, not "no result yet".
            for r in (c.get(f"/api/v1/jobs/{q}/result"),
                      c.get(f"/api/v1/jobs/{q}/export", params={"format": "gltf"})):
                said = r.json()["detail"]
                assert r.status_code == 404 and f"job {q} ended aborted" in said, said
                assert said.endswith("without a result") and "yet" not in said, said
        finally:
            assert c.post("/api/v1/rig/release").status_code == 200


@pytest.mark.parametrize(
    "path",
    [
        "/api/v1/jobs/../../../etc/passwd/result",
        "/api/v1/jobs/..%2F..%2Fetc%2Fpasswd/result",
        "/api/v1/jobs/%2e%2e/result",
        "/api/v1/jobs/1%00/result",
        "/api/v1/jobs/-1/result",
        "/api/v1/jobs/1e3/result",
        "/static/..%2F..%2Fapi%2Fapp.py",
        "/static/../daemon.py",
    ],
)
def test_traversal_attempts_get_4xx(daemon: Daemon, path: str) -> None:
    with httpx.Client(base_url=daemon.url) as c:
        # Send the path as written (no client-side normalisation of "..").
        r = c.send(c.build_request("GET", httpx.URL(daemon.url + path)))
        assert 400 <= r.status_code < 500, (path, r.status_code)
        assert b"import" not in r.content and b"root:" not in r.content


def test_mutations_need_a_key_and_respect_maintenance(daemon: Daemon) -> None:
    with daemon.client(key=None) as anon, daemon.client("x" * 30) as wrong, daemon.client() as c:
        assert anon.post("/api/v1/jobs", json=scan("anon")).status_code == 401
        assert wrong.post("/api/v1/jobs", json=scan("wrong")).status_code == 403
        assert anon.put("/api/v1/maintenance", json={"reason": "x"}).status_code == 401
        assert anon.get("/api/v1/jobs").status_code == 200
        r = c.put("/api/v1/maintenance", json={"reason": "swapping lamp L1"})
        assert r.json()["locked"] and r.json()["by"] == "tester"
        try:
            r = c.post("/api/v1/jobs", json=scan("locked"))
            assert r.status_code == 423 and "swapping lamp L1" in r.json()["detail"]
            assert anon.get("/api/v1/maintenance").json()["reason"] == "swapping lamp L1"
        finally:
            assert c.delete("/api/v1/maintenance").json()["locked"] is False
        big = {"plan": {"kind": "uniform", "specimen": "x" * (2 << 20)}}
        assert c.post("/api/v1/jobs", json=big).status_code == 413
