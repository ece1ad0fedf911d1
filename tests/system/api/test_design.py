"""The design endpoints on a live daemon: optimise pairs or a product rig, evaluate presets.

Results are checked against independent computations: the condition number from the basis rows
at the returned cells, device angles from the returned placement, and the TOML fragment parsed
back.
"""

from __future__ import annotations

import math
import threading
import time
import tomllib
from typing import Any

import numpy as np
import pytest

from gonio.brdf.tables import geometry as geo
from tests.system.api.conftest import DESIGN_LIMIT_S, Daemon

pytestmark = pytest.mark.system


def _kappa(basis: Any, pairs: list[dict[str, Any]]) -> float:
    """sigma_max / sigma_min of the pairs' basis rows over min(n, K) columns."""
    deg = np.array([[p["theta_h_deg"], p["theta_d_deg"], p["phi_d_deg"]] for p in pairs])
    th, td, pd = np.deg2rad(deg).T
    rows = basis.rows_at(th, td, pd)
    s = np.linalg.svd(rows[:, : min(len(pairs), rows.shape[1])], compute_uv=False)
    return float(s[0] / s[-1])


def _angle_deg(a: dict[str, Any], b: dict[str, Any]) -> float:
    va = geo.spherical_to_direction(np.deg2rad(a["theta_deg"]), np.deg2rad(a["phi_deg"]))
    vb = geo.spherical_to_direction(np.deg2rad(b["theta_deg"]), np.deg2rad(b["phi_deg"]))
    return float(np.degrees(np.arccos(np.clip(np.dot(va, vb), -1.0, 1.0))))


def _expected_log_rmse(basis: Any, pairs: list[dict[str, Any]], rotations: int,
                       span_deg: float = 180.0) -> float:
    """The joint fit's expected log_rmse of the returned cells (gonio.brdf.design.posterior)
    for ``rotations`` angles over ``span_deg`` (half a turn: the scans' default)."""
    from gonio.brdf.design.posterior import design_expected_log_rmse, prior_model

    deg = np.array([[p["theta_h_deg"], p["theta_d_deg"], p["phi_d_deg"]] for p in pairs])
    th, td, pd = np.deg2rad(deg).T
    return design_expected_log_rmse(prior_model(basis, rotations, span_deg=span_deg),
                             basis.rows_at(th, td, pd))


@pytest.mark.parametrize("objective", ["kappa", "posterior", None])
def test_optimised_pairs_respect_constraints_and_match_the_basis(
    daemon: Daemon, basis: Any, objective: str | None
) -> None:
    from gonio.brdf.design.pairs import DEFAULT_OBJECTIVE

    made_by = DEFAULT_OBJECTIVE if objective is None else objective
    # The greedy choice falls back to the kappa search past its time limit (CPU time of its
    # mount checks, about 2 s here), so it gets the most this daemon allows.
    body = {"pairs": 6, "max_elevation_deg": 70, "min_device_distance_deg": 12,
            "time_limit_s": 2 if made_by == "kappa" else DESIGN_LIMIT_S, "starts": 3,
            "descents": 3,
            "rotations": 12, "seed": 3,
            **({} if objective is None else {"objective": objective})}
    with daemon.client() as c:
        r = c.post("/api/v1/design", json=body)
    assert r.status_code == 200, r.text
    d = r.json()
    if made_by != "kappa" and d["fallback"] is not None:
        # A saturated machine can make the greedy choice overrun even that: then the design
        # must say so and be the kappa search's, checked below like any other.
        assert "time limit" in d["fallback"] and d["objective"] == "kappa", d["fallback"]
        made_by = "kappa"
    else:
        assert d["fallback"] is None
    assert d["objective"] == made_by
    assert d["name"] == "optimized" and d["n_pairs"] == 6 and len(d["pairs"]) == 6
    assert d["condition_number"] == pytest.approx(_kappa(basis, d["pairs"]), rel=1e-3)
    assert d["expected_log_rmse"] == pytest.approx(_expected_log_rmse(basis, d["pairs"], 12),
                                                   rel=1e-3)
    # Only the statistics of the search that ran.
    if made_by == "kappa":
        assert d["search"]["evaluations"] > 0 and d["greedy"] is None
    else:
        assert d["search"] is None and d["greedy"]["first"] == 3
        assert d["greedy"]["evaluations"] == 6 * d["greedy"]["candidates"] > 0
    devices = d["lights"] + d["sensors"]
    assert all(0 <= dev["theta_deg"] <= 70 + 1e-6 for dev in devices)
    closest = min(_angle_deg(a, b) for i, a in enumerate(devices) for b in devices[i + 1:])
    assert closest >= 12 - 1e-3
    assert d["min_device_distance_deg"] == pytest.approx(closest, abs=1e-2)
    assert d["roughness"]["rotations"] == 12 and d["roughness"]["n_effective"] > 0
    frag = tomllib.loads(d["rig_config_toml"])
    assert [p["light"] for p in frag["pairs"]] == [p["light"] for p in d["pairs"]]
    assert frag["lights"] == d["lights"] and frag["sensors"] == d["sensors"]
    # The expected-error choice weighs the cells the renderings see by default
    # (docs/science.md 7.2.2), says so, and records it in the fragment; a kappa design not.
    want_mix = 0.5 if made_by == "posterior" else 0.0
    assert d["render_mix"] == want_mix
    assert frag.get("design", {}).get("render_mix", 0.0) == want_mix


def test_product_rig_measures_every_pair(daemon: Daemon, basis: Any) -> None:
    body = {"lights": 2, "sensors": 3, "time_limit_s": 2, "starts": 2,
            "exclusions": ["cone:0,0,10"]}
    with daemon.client() as c:
        r = c.post("/api/v1/design", json=body)
    assert r.status_code == 200, r.text
    d = r.json()
    assert d["name"] == "product" and d["n_pairs"] == 6
    assert {(p["light"], p["sensor"]) for p in d["pairs"]} == {
        (f"L{a}", f"S{b}") for a in (1, 2) for b in (1, 2, 3)}
    assert tomllib.loads(d["rig_config_toml"])["pairs"] == "all"
    # No device inside the excluded cone around the normal.
    assert all(dev["theta_deg"] >= 10 - 1e-6 for dev in d["lights"] + d["sensors"])
    assert d["condition_number"] == pytest.approx(_kappa(basis, d["pairs"]), rel=1e-3)
    assert d["objective"] is None and d["search"] is None and d["greedy"] is None
    assert d["expected_log_rmse"] == pytest.approx(_expected_log_rmse(basis, d["pairs"], 8),
                                                   rel=1e-3)


@pytest.mark.parametrize(
    ("body", "message"),
    [
        ({"pairs": 4, "lights": 2, "sensors": 2}, "not both"),
        ({}, "say what to design"),
        ({"lights": 2}, "needs both"),
        ({"pairs": 4, "neighbourhood": 4}, "must be odd"),
        ({"pairs": 0}, "greater than or equal to 1"),
        ({"pairs": 4, "time_limit_s": DESIGN_LIMIT_S + 1}, "more than this daemon allows"),
        ({"pairs": 4, "exclusions": ["sphere:1,2"]}, "cannot read exclusion"),
        ({"pairs": 4, "max_elevation_deg": 95}, "less than 90"),
        ({"pairs": 4, "colour": "red"}, "Extra inputs are not permitted"),
        ({"pairs": 4, "objective": "entropy"}, "Input should be 'kappa' or 'posterior'"),
        ({"lights": 2, "sensors": 2, "objective": "posterior"},
         "a product rig is always designed by the condition number"),
        ({"pairs": 6, "colour_instrument": "MA99"}, "known instruments are MA68, MA98"),
        ({"lights": 2, "sensors": 2, "colour_instrument": "MA98"},
         "'colour_instrument' designs independent 'pairs'"),
        ({"pairs": 6, "colour_instrument": "MA98", "colour_weight": -2},
         "greater than or equal to 0"),
        ({"pairs": 3, "colour_instrument": "MA98"}, "need 5 pairs of their own"),
        ({"lights": 2, "sensors": 2, "render_mix": 0.5},
         "a product rig takes none (drop render_mix)"),
        ({"pairs": 4, "render_mix": 2}, "less than or equal to 1"),
        ({"pairs": 12, "max_elevation_deg": 10, "min_device_distance_deg": 30,
          "time_limit_s": 1}, ""),
    ],
)
def test_design_requests_with_mistakes_get_422(
    daemon: Daemon, body: dict[str, Any], message: str
) -> None:
    with daemon.client() as c:
        r = c.post("/api/v1/design", json=body)
    assert r.status_code == 422, r.text
    assert message in r.text


def test_design_needs_a_key_and_runs_one_at_a_time(daemon: Daemon) -> None:
    with daemon.client(key=None) as anon:
        assert anon.post("/api/v1/design", json={"pairs": 3}).status_code == 401
    # The condition-number search: it runs for its whole time limit.
    slow = {"pairs": 10, "starts": 100, "descents": 100, "time_limit_s": 2.5,
            "objective": "kappa"}
    first: dict[str, Any] = {}

    def run_first() -> None:
        with daemon.client() as c:
            first["r"] = c.post("/api/v1/design", json=slow)

    t = threading.Thread(target=run_first)
    t0 = time.monotonic()
    t.start()
    # Until the first search holds the service's design lock (however slowly a busy machine
    # gets there), not a fixed sleep that a saturated machine can outrun.
    deadline = time.monotonic() + 120
    while not daemon.app.state.service._design_lock.locked():
        assert t.is_alive() and time.monotonic() < deadline, "the first design never started"
        time.sleep(0.01)
    with daemon.client() as c:
        second = c.post("/api/v1/design", json={"pairs": 3, "time_limit_s": 1})
        # The event loop is not blocked by the running design: status reads still answer.
        assert c.get("/health").status_code == 200
    t.join(30)
    assert first["r"].status_code == 200, first["r"].text
    # The first search uses its whole time limit (10 000 descents do not finish sooner), so it
    # was still running when the second request came.
    assert first["r"].json()["search"]["seconds"] > 1.5
    assert time.monotonic() - t0 > 2.0
    assert second.status_code == 409 and "another design" in second.json()["detail"]


def test_presets_list_and_evaluate(daemon: Daemon, basis: Any) -> None:
    with daemon.client(key=None) as c:
        names = [p["name"] for p in c.get("/api/v1/design/presets").json()]
        assert names == ["MA68", "MA98", "BYK-mac", "MultiFX10"]
        r = c.get("/api/v1/design/presets/ma 98", params={"rotations": 16})
        assert r.status_code == 200, r.text
        d = r.json()
        assert d["name"] == "MA98" and d["n_pairs"] == 19 and d["search"] is None
        assert d["objective"] is None and d["greedy"] is None
        # Next to kappa, as for an optimized design: the joint fit's expected error.
        assert d["expected_log_rmse"] == pytest.approx(
            _expected_log_rmse(basis, d["pairs"], 16), rel=1e-3)
        assert d["roughness"]["rotations"] == 16
        # Light 1 of MA98 is at 45 deg in the plane of incidence.
        assert d["lights"][0]["theta_deg"] == pytest.approx(45.0)
        # Its nearest pair to the mirror: the 20 deg sensor under the 15 deg light, (20 - 15)
        # / 2 in the plane of incidence.
        assert d["mirror_gap_deg"] == pytest.approx(2.5, abs=1e-9)
        assert "within 2.5 degrees of the specimen normal" in d["mirror_gap"]
        kappa = d["condition_number"]
        assert kappa is None or kappa == pytest.approx(_kappa(basis, d["pairs"]), rel=1e-3)
        assert math.isfinite(d["roughness"]["n_effective"])
        r = c.get("/api/v1/design/presets/MA99")
        assert r.status_code == 404 and "MA68" in r.json()["detail"]
        assert c.get("/api/v1/design/presets/MA68", params={"rotations": 0}).status_code == 422
        # Over a full turn when asked: its own expected error; other arcs are refused.
        full = c.get("/api/v1/design/presets/MA68", params={"rotations": 8, "span_deg": 360})
        assert full.status_code == 200, full.text
        f = full.json()
        assert f["roughness"]["span_deg"] == 360 and f["roughness"]["rotations"] == 8
        assert f["expected_log_rmse"] == pytest.approx(
            _expected_log_rmse(basis, f["pairs"], 8, 360.0), rel=1e-3)
        bad = c.get("/api/v1/design/presets/MA68", params={"span_deg": 90})
        assert bad.status_code == 422 and "180 (half a turn) or 360" in bad.text, bad.text
