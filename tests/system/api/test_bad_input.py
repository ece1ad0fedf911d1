"""Bad input at the API door: every malformed value is a clear 422, none a 500, nothing stored.

The bodies are sent as raw bytes, so each case is exactly what a hand-written or fuzzed request
puts on the wire (``NaN``, ``Infinity`` and ``1e999`` are what Python's and JavaScript's JSON
writers emit for non-finite numbers).
"""

from __future__ import annotations

import json

import pytest

from tests.system.api.conftest import Daemon

pytestmark = pytest.mark.system

NON_FINITE = ["NaN", "Infinity", "-Infinity", "1e999"]

# (path, body template with {x} where the bad number goes, the field's name)
NUMBER_FIELDS = [
    ("/api/v1/jobs", '{{"plan": {{"kind": "uniform", "start_deg": {x}}}}}', "start_deg"),
    ("/api/v1/jobs", '{{"plan": {{"kind": "uniform", "exposure": {{"exposure_s": {x}}}}}}}',
     "exposure_s"),
    ("/api/v1/jobs", '{{"plan": {{"kind": "uniform", "backlash_deg": {x}}}}}', "backlash_deg"),
    ("/api/v1/jobs", '{{"plan": {{"kind": "adaptive", "threshold": {x}}}}}', "threshold"),
    ("/api/v1/jobs", '{{"plan": {{"kind": "calibration", "reference_albedo": {x}}}}}',
     "reference_albedo"),
    ("/api/v1/jobs", '{{"plan": {{"kind": "uniform", "faults": {{"retry_delay_s": {x}}}}}}}',
     "retry_delay_s"),
    ("/api/v1/jobs/dry-run", '{{"plan": {{"kind": "uniform", "start_deg": {x}}}}}',
     "start_deg"),
    ("/api/v1/design", '{{"pairs": 4, "time_limit_s": {x}}}', "time_limit_s"),
    ("/api/v1/design", '{{"pairs": 4, "max_elevation_deg": {x}}}', "max_elevation_deg"),
    ("/api/v1/rig/stage", '{{"action": "move", "angle_deg": {x}}}', "angle_deg"),
]


def _post(daemon: Daemon, path: str, body: str) -> tuple[int, object]:
    with daemon.client() as c:
        r = c.post(path, content=body.encode("utf-8", "surrogatepass"),
                   headers={"content-type": "application/json"})
    # The error body itself must be valid JSON (it once failed to render: NaN is not JSON).
    return r.status_code, json.loads(r.text)


def _jobs(daemon: Daemon) -> int:
    with daemon.client() as c:
        return len(c.get("/api/v1/jobs").json())


@pytest.mark.parametrize("x", NON_FINITE)
@pytest.mark.parametrize(("path", "template", "field"), NUMBER_FIELDS,
                         ids=[f"{p.rsplit('/', 1)[-1]}-{f}" for p, _, f in NUMBER_FIELDS])
def test_non_finite_numbers_are_422(
    daemon: Daemon, path: str, template: str, field: str, x: str
) -> None:
    before = _jobs(daemon)
    status, body = _post(daemon, path, template.format(x=x))
    assert status == 422, body
    assert isinstance(body, dict)
    detail = body["detail"]
    assert isinstance(detail, list) and detail
    assert any(field in [str(p) for p in d["loc"]] for d in detail), detail
    assert all(isinstance(d["msg"], str) and d["msg"] for d in detail)
    assert _jobs(daemon) == before


@pytest.mark.parametrize(
    ("specimen", "words"),
    [("\ud800", "unicode string"), ("brushed\u0000Al", "U+0000"), ("bell\u0007", "U+0007"),
     ("two\nlines", "U+000A")],
    ids=["lone-surrogate", "nul", "bell", "newline"],
)
def test_names_with_control_characters_or_broken_text_are_422(
    daemon: Daemon, specimen: str, words: str
) -> None:
    before = _jobs(daemon)
    # json.dumps writes a lone surrogate as the escape \ud800, as a browser would.
    body = json.dumps({"plan": {"kind": "uniform", "rotations": 2, "specimen": specimen}})
    status, answer = _post(daemon, "/api/v1/jobs", body)
    assert status == 422, answer
    assert isinstance(answer, dict)
    assert any(words in d["msg"] and "specimen" in d["loc"] for d in answer["detail"])
    assert _jobs(daemon) == before


def test_unicode_names_are_still_welcome(daemon: Daemon) -> None:
    body = json.dumps({"plan": {"kind": "uniform", "rotations": 4, "specimen": "Błękit ñ 漆"}})
    status, answer = _post(daemon, "/api/v1/jobs/dry-run", body)
    assert status == 200, answer


@pytest.mark.parametrize(
    "body",
    ['{"plan": {"kind": "uniform", "rotations": true}}',
     '{"plan": {"kind": "uniform", "rotations": 8.0}}',
     '{"plan": {"kind": "uniform", "rotations": "8"}}',
     '{"plan": {"kind": "uniform"}, "priority": false}',
     '{"plan": {"kind": "uniform", "exposure": {"averages": true}}}'],
    ids=["true", "float", "string", "priority-false", "averages-true"],
)
def test_counts_must_be_json_integers(daemon: Daemon, body: str) -> None:
    status, answer = _post(daemon, "/api/v1/jobs", body)
    assert status == 422, answer


def test_start_angle_outside_a_turn_says_the_equivalent(daemon: Daemon) -> None:
    status, answer = _post(daemon, "/api/v1/jobs/dry-run",
                           '{"plan": {"kind": "uniform", "start_deg": -500}}')
    assert status == 422
    assert isinstance(answer, dict)
    msg = answer["detail"][0]["msg"]
    # -500 + 2 x 360 = 220: the same specimen angle, which the user may send instead.
    assert "[0, 360)" in msg and "220" in msg


@pytest.mark.parametrize(("setting", "words"), [
    ('"rule": "bayes"', ["rule must be 'posterior'", "'vf'", "got 'bayes'"]),
    ('"rule": null', ["rule must be", "got None"]),
    ('"min_gain": -0.001', ["min_gain", "> 0", "got -0.001", "default 2e-05",
                            "larger stops refining sooner"]),
    ('"min_gain": 0', ["min_gain", "> 0", "got 0"]),
    ('"min_gain": "much"', ["valid number"]),
], ids=["unknown-rule", "null-rule", "negative-gain", "zero-gain", "text-gain"])
@pytest.mark.parametrize("path", ["/api/v1/jobs", "/api/v1/jobs/dry-run"])
def test_adaptive_rule_settings_are_checked_with_advice(
        daemon: Daemon, path: str, setting: str, words: list[str]) -> None:
    before = _jobs(daemon)
    status, answer = _post(daemon, path, '{"plan": {"kind": "adaptive", ' + setting + "}}")
    assert status == 422, answer
    assert isinstance(answer, dict)
    msgs = " ".join(str(d["msg"]) for d in answer["detail"])
    assert all(w in msgs for w in words), msgs
    assert _jobs(daemon) == before


@pytest.mark.parametrize(("setting", "words"), [
    ('"max_rotations": 0', ["max_rotations", "greater than 0"]),
    ('"max_rotations": 3601', ["max_rotations", "3600"]),
    ('"max_rotations": 3', ["max_rotations 3 is fewer than the first round's 4 angles",
                            "raise max_rotations or lower initial_rotations"]),
    ('"initial_rotations": 8, "max_rotations": 6', ["max_rotations 6", "first round's 8"]),
], ids=["zero", "above-cap", "below-default-start", "below-start"])
@pytest.mark.parametrize("path", ["/api/v1/jobs", "/api/v1/jobs/dry-run"])
def test_an_adaptive_cap_on_stage_angles_is_checked_with_advice(
        daemon: Daemon, path: str, setting: str, words: list[str]) -> None:
    before = _jobs(daemon)
    status, answer = _post(daemon, path, '{"plan": {"kind": "adaptive", ' + setting + "}}")
    assert status == 422, answer
    assert isinstance(answer, dict)
    detail = answer["detail"]
    msgs = detail if isinstance(detail, str) else " ".join(
        f"{d['loc']} {d['msg']}" for d in detail)
    assert all(w in msgs for w in words), msgs
    assert _jobs(daemon) == before


@pytest.mark.parametrize("plan", [
    '{"kind": "uniform", "span_deg": 90}', '{"kind": "adaptive", "span_deg": 720}',
    '{"kind": "uniform", "span_deg": "half"}'], ids=["quarter", "two-turns", "text"])
@pytest.mark.parametrize("path", ["/api/v1/jobs", "/api/v1/jobs/dry-run"])
def test_the_arc_of_the_angles_is_checked_with_advice(
        daemon: Daemon, path: str, plan: str) -> None:
    before = _jobs(daemon)
    status, answer = _post(daemon, path, '{"plan": ' + plan + "}")
    assert status == 422, answer
    assert isinstance(answer, dict)
    msgs = " ".join(str(d["msg"]) for d in answer["detail"])
    assert "span_deg" in msgs and "180 (half a turn" in msgs and "360 (a full turn" in msgs, msgs
    assert _jobs(daemon) == before


@pytest.mark.parametrize(
    "query", ["since=1e30", f"since={10**30}", f"job_id={10**30}", "job_id=1e30", "since=-1",
              "job_id=0"],
)
def test_event_stream_bounds(daemon: Daemon, query: str) -> None:
    with daemon.client() as c:
        r = c.get(f"/api/v1/events?{query}")
    assert r.status_code == 422, r.text
    assert isinstance(r.json()["detail"], list)


def test_huge_last_event_id_starts_live(daemon: Daemon) -> None:
    # A garbage or overflowing Last-Event-ID is ignored (the stream starts at "now"): the
    # stream opens instead of failing with an integer overflow in the store.
    with daemon.client() as c, c.stream(
        "GET", "/api/v1/events", headers={"Last-Event-ID": str(10**30)}
    ) as r:
        assert r.status_code == 200
        first = next(r.iter_lines())
        assert first.startswith("retry:")


def test_a_dry_run_refuses_a_misspelt_key_as_a_job_request_does(daemon: Daemon) -> None:
    # {"plan": ..., "priorty": 5} was checked as if the key were absent (200), while POST
    # /jobs refuses it (422 extra_forbidden).
    body = {"plan": {"kind": "uniform", "rotations": 4}, "priorty": 5}
    with daemon.client() as c:
        r = c.post("/api/v1/jobs/dry-run", json=body)
    assert r.status_code == 422, r.text
    assert r.json()["detail"][0]["loc"] == ["body", "priorty"]


def test_events_of_a_job_that_does_not_exist_are_404(daemon: Daemon) -> None:
    # ?job_id=999 used to open a stream that never said anything (200), so a mistyped id
    # looked like a quiet job; every other job route answers 404 for it.
    with daemon.client() as c:
        r = c.get("/api/v1/events?job_id=999999")
    assert r.status_code == 404, r.text
    assert "999999" in r.json()["detail"]


def test_a_body_that_is_not_json_says_so_and_what_to_send(daemon: Daemon) -> None:
    """A body with a stray comma answered "JSON decode error" and nothing more; one sent
    without its JSON content type (curl -d, a form post) "Input should be a valid
    dictionary". Both now say what was wrong and what to send; nothing is queued."""
    before = _jobs(daemon)
    status, answer = _post(daemon, "/api/v1/jobs", '{"plan": {"kind": "uniform",}}')
    assert status == 422, answer
    assert isinstance(answer, dict)
    (err,) = answer["detail"]
    assert err["type"] == "json_invalid"
    # The parser's own reason (Python's json module words a trailing comma so).
    assert err["msg"].startswith("the request body is not valid JSON (Expecting"), err
    assert "Content-Type: application/json" in err["msg"], err
    with daemon.client() as c:
        r = c.post("/api/v1/jobs", content=b'{"plan": {"kind": "uniform"}}',
                   headers={"content-type": "application/x-www-form-urlencoded"})
    assert r.status_code == 422, r.text
    msgs = [d["msg"] for d in r.json()["detail"]]
    assert any("must be a JSON object, sent with the header Content-Type: application/json"
               in m for m in msgs), msgs
    assert _jobs(daemon) == before
