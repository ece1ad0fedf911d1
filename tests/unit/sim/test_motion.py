"""Stage physics of the simulators: trapezoidal profiles, settling, retargeting, faults
(gonio.sim.motion)."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gonio.sim.motion import StageMotion, plan_phases


class FakeClock:
    """Wall clock the test advances by hand."""

    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


def make(**kw: float) -> tuple[StageMotion, FakeClock]:
    clock = FakeClock()
    params = {"speed_dps": 30.0, "accel_dps2": 60.0, "settle_s": 0.0, **kw}
    return StageMotion(clock=clock, **params), clock


def test_trapezoid_reaches_target_in_analytic_time() -> None:
    m, clock = make()
    m.move_to(90.0)
    # 30 deg/s reached after 0.5 s and 7.5 deg; 75 deg cruise = 2.5 s; total 3.5 s.
    clock.t += 0.5
    assert m.position_deg() == pytest.approx(7.5)
    assert m.velocity_dps() == pytest.approx(30.0)
    clock.t += 2.5
    assert m.position_deg() == pytest.approx(82.5)
    clock.t += 0.4999
    assert m.is_moving()
    clock.t += 0.0002
    assert not m.is_moving()
    assert m.position_deg() == pytest.approx(90.0)


def test_short_move_is_triangular_and_time_scale_speeds_it_up() -> None:
    m, clock = make(time_scale=10.0)
    m.move_to(-6.0)  # peak speed sqrt(60*6) ~ 19 deg/s < 30: no cruise, 2*sqrt(6/60) s
    total = 2 * math.sqrt(6.0 / 60.0)
    clock.t += total / 2 / 10.0
    assert m.position_deg() == pytest.approx(-3.0)
    assert abs(m.velocity_dps()) == pytest.approx(math.sqrt(60.0 * 6.0))
    clock.t += total / 2 / 10.0 + 1e-6
    assert m.position_deg() == pytest.approx(-6.0)


def test_settle_time_keeps_stage_moving_after_profile() -> None:
    m, clock = make(settle_s=0.2)
    m.move_to(1.0)
    clock.t += 2 * math.sqrt(1.0 / 60.0) + 0.1
    assert m.position_deg() == pytest.approx(1.0)
    assert m.is_moving()
    clock.t += 0.11
    assert not m.is_moving()


def test_a_command_to_where_the_stage_rests_does_not_ring() -> None:
    """Ringing follows a move: commanding the position the stage rests at moves nothing and
    leaves it at rest; during the ringing of a move the same command does not extend it."""
    m, clock = make(settle_s=0.2)
    m.move_to(0.0)
    assert not m.is_moving()
    m.move_to(1.0)
    end = 2 * math.sqrt(1.0 / 60.0)
    clock.t += end + 0.1
    m.move_to(1.0)  # still ringing: 0.1 s of the 0.2 s left
    assert m.is_moving()
    clock.t += 0.11
    assert not m.is_moving()
    m.move_to(1.0)
    assert not m.is_moving() and m.position_deg() == pytest.approx(1.0)


@settings(max_examples=60, deadline=None)
@given(
    p0=st.floats(-500, 500),
    v0=st.floats(-40, 40),
    target=st.floats(-500, 500),
    vmax=st.floats(1, 100),
    amax=st.floats(1, 500),
)
def test_planned_phases_end_at_rest_on_target(
    p0: float, v0: float, target: float, vmax: float, amax: float
) -> None:
    p, v = p0, v0
    for duration, a in plan_phases(p0, v0, target, vmax, amax):
        assert duration >= 0
        assert abs(a) <= amax + 1e-9
        p += v * duration + 0.5 * a * duration**2
        v += a * duration
    assert v == pytest.approx(0.0, abs=1e-6)
    assert p == pytest.approx(target, abs=1e-6)


def test_retarget_mid_move_blends_without_velocity_jump() -> None:
    m, clock = make()
    m.move_to(90.0)
    clock.t += 1.0
    v_before = m.velocity_dps()
    m.move_to(-10.0)  # behind the stage: it must brake first
    assert m.velocity_dps() == pytest.approx(v_before)
    clock.t += 0.01
    assert m.velocity_dps() < v_before
    clock.t += 20.0
    assert m.position_deg() == pytest.approx(-10.0)


def test_stop_decelerates_to_rest() -> None:
    m, clock = make()
    m.move_to(90.0)
    clock.t += 1.5  # cruising at 30 deg/s at 37.5 deg
    m.stop()
    clock.t += 0.5  # 30/60 s to stop, 7.5 deg further
    assert not m.is_moving()
    assert m.position_deg() == pytest.approx(45.0)


def test_stall_stops_short_and_clears_on_next_move() -> None:
    m, clock = make()
    m.arm_stall(0.25)
    m.move_to(40.0)
    clock.t += 10.0
    assert m.position_deg() == pytest.approx(10.0, abs=1e-6)
    assert m.stalled() and not m.is_moving()
    m.move_to(0.0)
    assert not m.stalled()


def test_overload_trips_and_blocks_moves_until_reset() -> None:
    m, clock = make()
    m.arm_overload(0.5)
    m.move_to(20.0)
    clock.t += 10.0
    assert m.overloaded()
    assert m.position_deg() == pytest.approx(10.0, abs=1e-6)
    m.move_to(0.0)
    clock.t += 10.0
    assert m.position_deg() == pytest.approx(10.0, abs=1e-6)  # no torque
    m.reset_overload()
    m.move_to(0.0)
    clock.t += 10.0
    assert m.position_deg() == pytest.approx(0.0)


@pytest.mark.parametrize("bad", [{"speed_dps": 0.0}, {"accel_dps2": -1.0}, {"time_scale": 0.0}])
def test_invalid_motion_parameters_are_refused(bad: dict[str, float]) -> None:
    with pytest.raises(ValueError, match="must be > 0"):
        StageMotion(**bad)


@pytest.mark.parametrize("v0", [1.7e-4, -3e-3, 2e-6])
def test_a_slow_creep_onto_the_target_still_ends_at_rest(v0: float) -> None:
    # Found by hypothesis: moving slowly with the target where the stage already is, the
    # stopping distance is below any position tolerance, yet the speed must still reach zero.
    p, v = 10.0, v0
    for duration, a in plan_phases(10.0, v0, 10.0, 30.0, 60.0):
        p += v * duration + 0.5 * a * duration**2
        v += a * duration
    assert v == pytest.approx(0.0, abs=1e-9)
    assert p == pytest.approx(10.0, abs=1e-6)
