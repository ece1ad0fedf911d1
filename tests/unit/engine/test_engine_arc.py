"""The engine measures what an auto-arc plan's rounds ask (gonio.plans.rounds.ArcRounds), and a
resumed job goes on on the arc its stored ``arc_test`` event chose.

The in-memory rig's sensors follow ``1 + 0.5 cos 2 (alpha - phi)``, noiseless: twofold
symmetric, so a fresh job stays on half a turn. Its three pairs lie within 12 deg of one plane,
so the first round reads two opposites (``gonio.plans.arc.opposites_needed``).
"""

from __future__ import annotations

import asyncio

import pytest

from gonio.engine import ScanEngine
from gonio.jobstates import JobState
from gonio.plans.arc import ARC_TEST_EVENT, fill_angles, first_round_angles
from gonio.plans.models import ExposureSettings, UniformPlan
from gonio.plans.rounds import NextRound
from gonio.rigdescription import RigDescription
from gonio.sim.memrig import MemRig
from gonio.store import JobStore

FAST = ExposureSettings(exposure_s=0.002, light_settle_s=0.0, dark="once")


def _job(store: JobStore, plan: UniformPlan, desc: RigDescription) -> int:
    return store.create_job(kind=plan.kind, specimen="s", plan=plan.model_dump(mode="json"),
                            rig=desc.model_dump(mode="json")).id


def test_a_symmetric_specimen_is_measured_over_half_a_turn_once_tested() -> None:
    plan = UniformPlan(rotations=8, arc="auto", exposure=FAST)
    rig = MemRig(3600.0)
    desc = RigDescription.from_rig(rig)
    store = JobStore(":memory:")
    job = _job(store, plan, desc)
    assert asyncio.run(ScanEngine(rig, store, job, plan, desc).run()) is JobState.RUNNING
    steps = store.steps(job)
    assert sorted(s.specimen_deg for s in steps) == pytest.approx(
        sorted(first_round_angles(0.0, 8, opposites=2)))
    assert {s.round for s in steps} == {0}
    tests = [e for e in store.events_after(0, job_id=job) if e.type == ARC_TEST_EVENT]
    assert len(tests) == 1 and tests[0].data["symmetric"] and tests[0].data["arc_deg"] == 180


def test_a_resumed_job_fills_the_full_turn_it_chose_without_testing_again() -> None:
    """Job 2 holds job 1's first round (symmetric readings) and an arc_test event that chose
    the full turn, as a job interrupted right after its test would: resumed, it measures the
    fill round and records no second test, each angle once."""
    plan = UniformPlan(rotations=8, arc="auto", exposure=FAST)
    rig = MemRig(3600.0)
    desc = RigDescription.from_rig(rig)
    store = JobStore(":memory:")
    first = _job(store, plan, desc)
    asyncio.run(ScanEngine(rig, store, first, plan, desc).run())
    job = _job(store, plan, desc)
    steps = store.steps(first)
    store.add_steps(job, [(s.angle_index, s.round, s.specimen_deg, s.position_deg)
                          for s in steps])
    by_angle: dict[int, list] = {}
    for r in store.readings(first):
        by_angle.setdefault(r.angle_index, []).append(r)
    for s in steps:
        store.commit_angle(job, s.angle_index, s.actual_deg or s.position_deg,
                           by_angle[s.angle_index])
    store.append_event(job, ARC_TEST_EVENT, {"symmetric": False, "arc_deg": 360.0,
                                             "statistic": 999.0, "dof": 60, "p_value": 0.0})
    store.set_state(job, JobState.RUNNING)
    rig2 = MemRig(3600.0)
    assert asyncio.run(ScanEngine(rig2, store, job, plan, desc).run()) is JobState.RUNNING
    after = store.steps(job)
    fill = [s for s in after if s.round == 1]
    assert sorted(s.specimen_deg for s in fill) == pytest.approx(fill_angles(0.0, 8, opposites=2))
    assert all(s.done for s in after) and len(after) == 16
    keys = [(r.angle_index, r.light, r.sensor) for r in store.readings(job)]
    assert len(keys) == len(set(keys)) == 16 * 3
    assert [e.type for e in store.events_after(0, job_id=job)].count(ARC_TEST_EVENT) == 1
    # The resumed rig measured only the fill round's angles.
    assert sorted(m % 360 for m in rig2.mstage.moves) == pytest.approx(
        fill_angles(0.0, 8, opposites=2))


class _BeyondTravel:
    """Rounds (gonio.plans.rounds.Rounds) that ask, after the first round, for an angle the
    stage's travel cannot reach: what a rig config edited between submission and a later
    round would do."""

    async def next_round(self, angles_deg: object, values: object, planned_angles: int,
                         last_round: int) -> NextRound:
        return NextRound([300.0] if last_round == 0 else [])


def test_a_round_the_travel_cannot_reach_fails_the_job_with_the_reason() -> None:
    """Not an internal error: the job fails naming the round and the travel, and the first
    round's readings stay stored."""
    plan = UniformPlan(rotations=4, exposure=FAST)
    rig = MemRig(3600.0)
    desc = RigDescription.from_rig(rig).model_copy(
        update={"stage_min_deg": -10.0, "stage_max_deg": 200.0})
    store = JobStore(":memory:")
    job = _job(store, plan, desc)
    engine = ScanEngine(rig, store, job, plan, desc)
    engine.rounds = _BeyondTravel()
    assert asyncio.run(engine.run()) is JobState.FAILED
    row = store.get_job(job)
    assert "round 1 cannot be measured" in (row.reason or "")
    assert "internal error" not in (row.reason or "")
    assert len(store.readings(job)) == 4 * 3  # the first round's 4 angles x 3 pairs, kept
