"""A stage simulator's fault plan: counters count down, flags stay, moves consume theirs."""

from __future__ import annotations

import threading

import pytest

from gonio.sim.faults import FaultPlan


def test_counters_count_down_one_reply_each() -> None:
    plan = FaultPlan()
    plan.set(drop_replies=2, corrupt_replies=1)
    assert [plan.take_drop() for _ in range(3)] == [True, True, False]
    assert [plan.take_corrupt() for _ in range(2)] == [True, False]


def test_silence_stays_until_cleared() -> None:
    plan = FaultPlan()
    plan.set(silent=True)
    assert plan.is_silent() and plan.is_silent()
    plan.clear()
    assert not plan.is_silent()


def test_a_move_fault_is_consumed_by_the_next_move() -> None:
    plan = FaultPlan()
    plan.set(stall_next_move=True, stall_fraction=0.25, overload_next_move=True)
    assert plan.take_stall() == 0.25 and plan.take_stall() is None
    assert plan.take_overload() and not plan.take_overload()


@pytest.mark.parametrize(("fraction", "used"), [(-0.5, 0.0), (1.0, 0.99), (7.0, 0.99)])
def test_a_stall_stops_short_of_the_target(fraction: float, used: float) -> None:
    """The fraction travelled is held in [0, 0.99]: a stalled move never arrives."""
    plan = FaultPlan(stall_next_move=True, stall_fraction=fraction)
    assert plan.take_stall() == used


def test_clear_disarms_everything() -> None:
    plan = FaultPlan(corrupt_replies=3, drop_replies=3, silent=True, stall_next_move=True,
                     overload_next_move=True)
    plan.clear()
    assert not (plan.take_corrupt() or plan.take_drop() or plan.is_silent()
                or plan.take_overload())
    assert plan.take_stall() is None


def test_an_unknown_fault_is_refused_with_the_known_ones() -> None:
    plan = FaultPlan()
    with pytest.raises(ValueError, match=r"unknown stage fault\(s\) \['jam'\]; known: "
                                         r"\['corrupt_replies', 'drop_replies', "):
        plan.set(jam=True, drop_replies=1)
    assert not plan.take_drop()  # nothing of a refused call is armed
    with pytest.raises(ValueError, match="unknown"):
        plan.set(_lock=None)


def test_arming_from_threads_loses_no_count() -> None:
    plan = FaultPlan()
    taken = []

    def consume() -> None:
        taken.extend(plan.take_drop() for _ in range(500))

    plan.set(drop_replies=600)
    threads = [threading.Thread(target=consume) for _ in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert sum(taken) == 600 and plan.drop_replies == 0
