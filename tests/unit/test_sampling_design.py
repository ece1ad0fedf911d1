"""Sampling design as the service offers it: the request's checks, and results whose geometry
is checked against hand-worked cells and the request's own mounting limits."""

from __future__ import annotations

import math
import re
import tomllib

import numpy as np
import pytest
from pydantic import ValidationError

from gonio.brdf.design.errors import FeasibilityError
from gonio.brdf.design.presets import get_preset
from gonio.sampling_design import DesignRequest, evaluate_preset, run_design
from tests.unit.engine.test_adaptive_posterior import BASIS


@pytest.mark.parametrize(("fields", "message"), [
    ({}, "say what to design: 'pairs' (independent pairs) or 'lights' and 'sensors'"),
    ({"pairs": 3, "lights": 2}, "give either 'pairs' or 'lights' and 'sensors', not both"),
    ({"lights": 2}, "a product rig needs both 'lights' and 'sensors'"),
    ({"lights": 2, "sensors": 2, "objective": "posterior"},
     "a product rig is always designed by the condition number"),
    ({"pairs": 3, "neighbourhood": 4}, "'neighbourhood' must be odd, got 4"),
    ({"pairs": 41}, "less than or equal to 40"),
    ({"pairs": 3, "max_elevation_deg": 90}, "less than 90"),
    ({"pairs": 3.0}, "valid integer"),
    ({"pairs": 3, "time_limit_s": math.nan}, "finite number"),
    ({"pairs": 3, "colour": "red"}, "Extra inputs are not permitted"),
    ({"pairs": 6, "colour_instrument": "MA99"}, "known instruments are MA68, MA98"),
    ({"lights": 2, "sensors": 2, "colour_instrument": "MA98"},
     "'colour_instrument' designs independent 'pairs' by the expected error"),
    ({"pairs": 6, "colour_instrument": "MA98", "objective": "kappa"},
     "drop objective 'kappa'"),
    ({"pairs": 6, "colour_instrument": "MA98", "colour_weight": -1},
     "greater than or equal to 0"),
    ({"pairs": 6, "render_mix": 1.5}, "less than or equal to 1"),
    ({"pairs": 6, "render_mix": math.nan}, "finite number"),
    ({"lights": 2, "sensors": 2, "render_mix": 0.5},
     "a product rig takes none (drop render_mix)"),
    ({"pairs": 6, "objective": "kappa", "render_mix": 0.5},
     "drop objective 'kappa' or render_mix"),
    ({"pairs": 6, "colour_instrument": "MA98", "render_mix": 0.5}, "cannot be combined"),
])
def test_a_request_that_cannot_be_designed_is_refused(fields: dict[str, object],
                                                      message: str) -> None:
    with pytest.raises(ValidationError, match=re.escape(message)):
        DesignRequest.model_validate(fields)


def test_the_constraints_carry_the_limits_and_exclusions() -> None:
    c = DesignRequest(pairs=3, max_elevation_deg=60, min_separation_deg=15,
                      exclusions=["cone:30,90,10"]).constraints()
    assert (c.max_elevation_deg, c.min_separation_deg, c.min_device_distance_deg) == (60, 15, 10)
    assert len(c.exclusions) == 1


def test_an_unreadable_exclusion_is_a_feasibility_error() -> None:
    with pytest.raises(FeasibilityError, match="cone"):
        DesignRequest(pairs=3, exclusions=["cone:30"]).constraints()


def test_a_preset_is_described_with_hand_worked_cells() -> None:
    """MA68: a light at 45 deg, sensors in its plane at 0, 30, 65 deg (same side) and 20, 30
    deg (other side). In the plane the half vector lies at the mean of the signed elevations
    and theta_d is half their difference: (45 + s) / 2 and |45 - s| / 2, with s = -20, -30 on
    the other side."""
    result = evaluate_preset(BASIS, get_preset("MA68"), rotations=8)
    signed = [0.0, 30.0, 65.0, -20.0, -30.0]
    got = [(p.theta_h_deg, p.theta_d_deg, p.phi_d_deg) for p in result.pairs]
    want = [(abs(45 + s) / 2, abs(45 - s) / 2, 0.0) for s in signed]
    np.testing.assert_allclose(got, want, atol=1e-9)
    assert (result.name, result.n_pairs, result.objective) == ("MA68", 5, None)
    assert [(s.theta_deg, s.phi_deg) for s in result.sensors] == [
        (0.0, 0.0), (30.0, 0.0), (65.0, 0.0), (20.0, 180.0), (30.0, 180.0)]
    assert result.roughness.rotations == 8 and result.roughness.span_deg == 180.0
    assert result.condition_number is not None and result.condition_number >= 1.0
    # Its mirror gap: the least of those theta_h, the 30 deg sensor on the far side's 7.5.
    assert result.mirror_gap_deg == pytest.approx(min(w[0] for w in want), abs=1e-9)
    assert result.mirror_gap is not None and "within 7.5 degrees" in result.mirror_gap


def test_a_designed_rig_keeps_to_the_requested_limits() -> None:
    req = DesignRequest(pairs=3, starts=1, descents=1, objective="kappa", max_elevation_deg=60,
                        min_separation_deg=20, min_device_distance_deg=12)
    result = run_design(BASIS, req)
    assert result.n_pairs == 3 and result.objective == "kappa" and result.search is not None
    devices = result.lights + result.sensors
    assert all(d.theta_deg <= 60 + 1e-6 and 0 <= d.phi_deg < 360 for d in devices)
    assert result.min_device_distance_deg >= 12 - 1e-6

    def vec(d: object) -> np.ndarray:
        t, p = math.radians(d.theta_deg), math.radians(d.phi_deg)  # type: ignore[attr-defined]
        return np.array([math.sin(t) * math.cos(p), math.sin(t) * math.sin(p), math.cos(t)])

    # device angles are given to 1e-4 deg, so a separation at the limit reads up to ~3e-4 short
    named = {d.name: d for d in devices}
    for pair in result.pairs:
        cos = float(vec(named[pair.light]) @ vec(named[pair.sensor]))
        assert math.degrees(math.acos(min(1.0, cos))) >= 20 - 1e-3
    # the fragment to paste into a rig config says the same
    frag = tomllib.loads(result.rig_config_toml)
    assert [(d["name"], d["theta_deg"]) for d in frag["lights"]] == [
        (d.name, d.theta_deg) for d in result.lights]
    assert [(p["light"], p["sensor"]) for p in frag["pairs"]] == [
        (p.light, p.sensor) for p in result.pairs]


def test_a_product_rig_measures_every_light_with_every_sensor() -> None:
    result = run_design(BASIS, DesignRequest(lights=2, sensors=2, starts=1))
    assert result.name == "product" and result.objective is None
    assert sorted((p.light, p.sensor) for p in result.pairs) == [
        ("L1", "S1"), ("L1", "S2"), ("L2", "S1"), ("L2", "S2")]


def test_the_renderings_weighting_is_the_default_and_can_be_asked_for_or_off() -> None:
    """Pairs are chosen with the standard renderings' cell weighting at one half unless the
    request says otherwise (docs/science.md 7.2.2); the result says which; ``render_mix`` 0
    is the design weighing cells as log_rmse does alone, the core's plain expected-error
    design."""
    from gonio.brdf.design.constraints import RigConstraints
    from gonio.brdf.design.posterior import posterior_design

    default = run_design(BASIS, DesignRequest(pairs=4))
    assert default.render_mix == 0.5 and default.objective == "posterior"
    plain = run_design(BASIS, DesignRequest(pairs=4, render_mix=0))
    assert plain.render_mix == 0.0
    core = posterior_design(BASIS, 4, RigConstraints())
    got = sorted((p.theta_h_deg, p.theta_d_deg) for p in plain.pairs)
    want = sorted((float(c[0]), float(c[1])) for c in np.rad2deg(core.cells))
    np.testing.assert_allclose(got, want, atol=1e-9)
    assert run_design(BASIS, DesignRequest(pairs=4, render_mix=1)).render_mix == 1.0
    # Nothing to weigh: a colour design and a product rig report 0.
    assert run_design(BASIS, DesignRequest(pairs=7, colour_instrument="ma98")).render_mix == 0
    assert run_design(BASIS, DesignRequest(lights=2, sensors=2, starts=1)).render_mix == 0


def test_a_colour_request_reports_its_colour_pairs() -> None:
    """MA98 has five in-plane geometries with aspecular angles up to 25 degrees; a colour
    design of 7 pairs gives them the first five, and a plain design none."""
    result = run_design(BASIS, DesignRequest(pairs=7, colour_instrument="ma98"))
    assert result.n_pairs == 7 and result.colour_pairs == 5
    assert result.objective == "posterior" and result.fallback is None
    assert run_design(BASIS, DesignRequest(pairs=3)).colour_pairs == 0
    # The fragment to merge into a rig config records the colour design in [design].
    design = tomllib.loads(result.rig_config_toml)["design"]
    assert design == {"rotations": 8, "span_deg": 180.0, "pairs": 7,
                      "colour_instrument": "MA98", "colour_weight": 100.0}
    # A plain design records the renderings' weighting that chose it (as `gonio design -o`
    # does), an unweighted one nothing.
    assert tomllib.loads(run_design(BASIS, DesignRequest(pairs=3)).rig_config_toml)[
        "design"] == {"rotations": 8, "span_deg": 180.0, "pairs": 3, "render_mix": 0.5}
    assert "design" not in tomllib.loads(run_design(BASIS, DesignRequest(pairs=3, render_mix=0))
                                         .rig_config_toml)
