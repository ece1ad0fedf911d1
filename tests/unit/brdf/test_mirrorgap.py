"""A layout's mirror gap (gonio.brdf.mirrorgap): the least half-vector tilt over its pairs, and
what a result and a dry run say of it (issue 23 item 4).

Expected values come from plane geometry: a light at polar angle ``ti`` and a sensor at ``to``
in the plane of incidence on the far side of the normal have a half vector tilted by
``|ti - to| / 2`` (the bisector of two directions in one plane), so a sensor at aspecular angle
``as`` has ``th_h = |as| / 2``; the industrial geometries' aspecular angles are the standards'
(ASTM E2194 / DIN 6175-2: 15 deg the nearest of MA68's, a 20 deg sensor under the 15 deg light
MA98's nearest, 5 deg)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from gonio.brdf.design.presets import get_preset
from gonio.brdf.mirrorgap import (
    MIRROR_GAP_LIMIT_DEG,
    cells_gap_deg,
    gap_clause,
    gap_note,
    mirror_gap_deg,
)
from gonio.figures import headline_error
from gonio.hal import LabDirection, PairSpec
from gonio.plans.dryrun import dry_run
from gonio.plans.models import CalibrationPlan, ExposureSettings, UniformPlan
from gonio.rigdescription import LightInfo, RigDescription, SensorInfo


def _unit(theta_deg: float, phi_deg: float) -> list[float]:
    """The lab direction at polar ``theta_deg``, azimuth ``phi_deg`` (the rig config's)."""
    return list(LabDirection(theta_deg, phi_deg).vector())


@pytest.mark.parametrize(("ti", "to", "expected"), [
    (45.0, 45.0, 0.0),     # the mirror direction itself
    (45.0, 30.0, 7.5),     # aspecular 15
    (45.0, 20.0, 12.5),    # aspecular 25
    (15.0, 20.0, 2.5),     # aspecular -5 under the 15 deg light
    (60.0, 0.0, 30.0),     # sensor on the normal
])
def test_an_in_plane_pair_tilts_by_half_its_aspecular_angle(ti: float, to: float,
                                                             expected: float) -> None:
    gap = mirror_gap_deg([_unit(ti, 0.0)], [_unit(to, 180.0)])
    assert gap == pytest.approx(expected, abs=1e-9)


def test_the_gap_is_the_nearest_pair_and_the_frame_turn_keeps_it() -> None:
    lights = [_unit(45.0, 0.0), _unit(45.0, 0.0), _unit(45.0, 0.0)]
    sensors = [_unit(65.0, 0.0), _unit(20.0, 180.0), _unit(30.0, 180.0)]
    assert mirror_gap_deg(lights, sensors) == pytest.approx(7.5, abs=1e-9)
    # Turning the specimen about its normal turns both directions alike: the tilt stays.
    turn = math.radians(37.0)
    rot = np.array([[math.cos(turn), -math.sin(turn), 0.0],
                    [math.sin(turn), math.cos(turn), 0.0], [0.0, 0.0, 1.0]])
    assert mirror_gap_deg(np.array(lights) @ rot.T, np.array(sensors) @ rot.T) == \
        pytest.approx(7.5, abs=1e-9)


@pytest.mark.parametrize(("preset", "expected"), [("MA68", 7.5), ("MA98", 2.5),
                                                  ("BYK-mac", 7.5)])
def test_the_industrial_geometries_gaps_are_half_their_nearest_aspecular_angle(
        preset: str, expected: float) -> None:
    li, so = get_preset(preset).directions()
    assert mirror_gap_deg(li, so) == pytest.approx(expected, abs=1e-6)
    cells, _ = get_preset(preset).cells()
    assert cells_gap_deg(cells) == pytest.approx(expected, abs=1e-6)


def test_bad_layouts_are_refused_saying_what_was_wrong() -> None:
    with pytest.raises(ValueError, match=r"\(n, 3\).*got \(0, 3\)"):
        mirror_gap_deg(np.zeros((0, 3)), np.zeros((0, 3)))
    with pytest.raises(ValueError, match=r"got \(2, 3\) and \(1, 3\)"):
        mirror_gap_deg([_unit(10, 0), _unit(20, 0)], [_unit(10, 180)])
    with pytest.raises(ValueError, match="above the specimen"):
        mirror_gap_deg([[0.0, 0.0, 1.0]], [[0.0, 0.0, -1.0]])
    with pytest.raises(ValueError, match="finite unit vectors"):
        mirror_gap_deg([[0.0, 0.0, 2.0]], [_unit(30, 180)])  # not unit: no silent wrong gap
    with pytest.raises(ValueError, match="finite unit vectors"):
        mirror_gap_deg([[np.nan, 0.0, 1.0]], [_unit(30, 180)])
    with pytest.raises(ValueError, match=r"\(n, 3\)"):
        cells_gap_deg(np.zeros((4,)))
    with pytest.raises(ValueError, match="finite"):
        cells_gap_deg([[np.nan, 0.1, 0.2]])


def test_the_note_is_said_above_the_limit_only() -> None:
    assert gap_note(0.0) is None
    assert gap_note(MIRROR_GAP_LIMIT_DEG) is None
    assert gap_note(float("nan")) is None
    note = gap_note(7.0)
    assert note is not None
    # The half vector's tilt, and the in-plane sensor's angle from the mirror direction
    # (twice it) that the industrial geometries are named by.
    assert "half vector comes within 7.0 degrees of the specimen normal" in note
    assert "its sensor 14 degrees off the light's mirror direction" in note
    assert "predicted_log_rmse" in note and "add a pair at the mirror direction" in note


def test_the_headline_states_the_gap_without_marking_the_number() -> None:
    note = gap_note(7.5)
    plain = headline_error({"predicted_log_rmse": 0.05, "mirror_gap_deg": 0.0})
    noted = headline_error({"predicted_log_rmse": 0.05, "mirror_gap_deg": 7.5,
                            "mirror_gap": note})
    assert plain is not None and noted is not None
    assert "Note:" not in plain["meaning"] and "mirror_gap" not in plain
    assert noted["text"] == plain["text"] == "0.050"
    assert noted["meaning"] == f"{plain['meaning']} Note: {note}."
    assert noted["mirror_gap"] == note
    # With the highlight-not-read warning, which already says to read a pair near the mirror
    # direction, the meaning gives the gap alone; the metric keeps the whole note.
    both = headline_error({"predicted_log_rmse": 0.05, "mirror_gap_deg": 7.5,
                           "mirror_gap": note, "highlight_not_read": "the highlight is not read"})
    assert both is not None and both["mirror_gap"] == note
    assert both["meaning"].endswith(f"Note: {gap_clause(7.5)}.")
    assert note not in both["meaning"]


def _rig(sensors: list[tuple[float, float]]) -> RigDescription:
    """One light at 30 deg, sensors in the plane of incidence on the far side."""
    return RigDescription(
        stage_min_deg=-360.0, stage_max_deg=720.0, speed_dps=90.0, accel_dps2=360.0,
        lights=(LightInfo(name="L", theta_deg=30.0, phi_deg=0.0),),
        sensors=tuple(SensorInfo(name=f"S{k}", theta_deg=t, phi_deg=p, channels=("Y",))
                      for k, (t, p) in enumerate(sensors)),
        pairs=tuple(PairSpec(light="L", sensor=f"S{k}") for k in range(len(sensors))))


FAST = ExposureSettings(exposure_s=0.002, light_settle_s=0.0, dark="once")


def test_the_dry_run_gives_the_layouts_gap_before_the_scan() -> None:
    plan = UniformPlan(rotations=4, span_deg=180, exposure=FAST)
    gapped = dry_run(plan, _rig([(40.0, 180.0), (50.0, 180.0)]))
    assert gapped.mirror_gap_deg == pytest.approx(5.0, abs=1e-9)  # (40 - 30) / 2
    assert gapped.mirror_gap == gap_note(5.0)
    assert gapped.warnings == []  # a fact of the layout, not a warning
    on_mirror = dry_run(plan, _rig([(30.0, 180.0), (50.0, 180.0)]))
    assert on_mirror.mirror_gap_deg == pytest.approx(0.0, abs=1e-9)
    assert on_mirror.mirror_gap is None
    # A plan that measures some of the rig's pairs: the gap of those it measures.
    subset = UniformPlan(rotations=4, span_deg=180, exposure=FAST,
                         pairs=[PairSpec(light="L", sensor="S1")])
    assert dry_run(subset, _rig([(30.0, 180.0), (50.0, 180.0)])).mirror_gap_deg == \
        pytest.approx(10.0, abs=1e-9)  # (50 - 30) / 2: the mirror pair is not measured
    calibration = dry_run(CalibrationPlan(reference_albedo=0.99, rotations=2, exposure=FAST),
                          _rig([(40.0, 180.0)]))
    assert calibration.mirror_gap_deg is None and calibration.mirror_gap is None
