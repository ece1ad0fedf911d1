"""Property-based fuzzing of every endpoint from the OpenAPI schema (schemathesis + hypothesis).

Each operation gets a bounded number of generated requests (valid and invalid), sent with and
without a valid key to a real daemon on a simulated rig. Properties: no 5xx, ever; every answer
conforms to the committed schema (its status code is documented for the operation, its content
type and body match what is documented); the daemon stays consistent afterwards (every job
readable, a fresh scan still completes).
"""

from __future__ import annotations

import json
import time

import hypothesis.strategies as st
import pytest
import schemathesis
from hypothesis import HealthCheck, given, settings
from schemathesis import checks as st_checks

from gonio.api.schema import SCHEMA_FILE
from tests.system.api.conftest import Daemon

pytestmark = pytest.mark.system

MAX_EXAMPLES = 12
CHECKS = [
    st_checks.not_a_server_error,
    st_checks.status_code_conformance,
    st_checks.content_type_conformance,
    st_checks.response_schema_conformance,
    st_checks.response_headers_conformance,
]
# Streams never end by themselves; the event stream is exercised by the scan-flow tests.
SKIP = {("GET", "/api/v1/events")}
BUDGET_S = 60.0


def test_no_endpoint_answers_5xx_and_state_stays_consistent(daemon: Daemon,
                                                           no_export_fits: None) -> None:
    schema = schemathesis.openapi.from_dict(json.loads(SCHEMA_FILE.read_text()))
    ops = [r.ok() for r in schema.get_all_operations()]
    ops = [op for op in ops if (op.method.upper(), op.path) not in SKIP]
    assert len(ops) > 20
    t0 = time.monotonic()
    failures: list[str] = []
    calls = 0

    for op in ops:
        @settings(max_examples=MAX_EXAMPLES, deadline=None, database=None,
                  suppress_health_check=list(HealthCheck))
        @given(case=op.as_strategy(), keyed=st.booleans())
        def check(case: schemathesis.Case, keyed: bool) -> None:
            nonlocal calls
            headers = {"X-API-Key": daemon.key} if keyed else {}
            # Generous: an export of a result without stored fits fits them on demand, which
            # took more than 20 s once on an oversubscribed machine (a timeout is not an answer
            # this test judges; no 5xx and the schema are).
            response = case.call(base_url=daemon.url, headers=headers, timeout=120)
            calls += 1
            try:
                case.validate_response(response, checks=CHECKS)
            except (Exception, BaseExceptionGroup) as exc:  # collect all, report together
                failures.append(f"{case.method} {case.formatted_path} -> {response.status_code}: "
                                f"{response.text[:200]}\n    {str(exc)[:400]}")

        if time.monotonic() - t0 > BUDGET_S:
            break
        check()

    assert not failures, "\n".join(failures[:20])
    assert calls >= len(ops)  # every operation was actually exercised

    # No corruption: undo what the fuzzer may have switched on, then the daemon works normally.
    with daemon.client() as c:
        c.delete("/api/v1/maintenance")
        c.post("/api/v1/rig/release")
        for job in c.get("/api/v1/jobs").json():
            detail = c.get(f"/api/v1/jobs/{job['id']}")
            assert detail.status_code == 200, detail.text
            assert detail.json()["state"] in {"queued", "running", "paused", "suspended",
                                              "reconstructing", "completed", "failed",
                                              "aborted", "halted"}
            if job["state"] == "queued":
                c.post(f"/api/v1/jobs/{job['id']}/cancel")
            elif job["state"] in ("running", "paused", "suspended", "reconstructing"):
                c.post(f"/api/v1/jobs/{job['id']}/abort")
        r = c.post("/api/v1/jobs", json={"plan": {"kind": "uniform", "rotations": 3,
                                                  "exposure": {"exposure_s": 0.005}}})
        assert r.status_code == 201, r.text
        job_id = r.json()["id"]
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline:
            state = c.get(f"/api/v1/jobs/{job_id}").json()["state"]
            if state in ("completed", "failed", "aborted", "halted"):
                break
            time.sleep(0.2)
        assert state == "completed"


def test_event_stream_rejects_bad_parameters(daemon: Daemon) -> None:
    with daemon.client(key=None) as c:
        assert c.get("/api/v1/events", params={"since": -1}).status_code == 422
        assert c.get("/api/v1/events", params={"since": "x"}).status_code == 422
