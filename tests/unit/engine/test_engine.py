"""The engine on an in-memory rig: sequencing, checkpoints, control, faults, adaptive rounds."""

from __future__ import annotations

import asyncio
from collections.abc import Callable

import numpy as np
import pytest

from gonio import hal
from gonio.calibration import readings_array
from gonio.engine import ScanEngine
from gonio.jobstates import JobState
from gonio.plans.models import AdaptivePlan, AnyPlan, ExposureSettings, FaultPolicy, UniformPlan
from gonio.rigdescription import RigDescription
from gonio.sim.memrig import MemRig
from gonio.store import JobStore, ReadingRow, StepRow

FAST = ExposureSettings(exposure_s=0.002, light_settle_s=0.0, dark="once")
QUICK_FAULTS = FaultPolicy(max_retries=3, retry_delay_s=0.005, resume_settle_s=0.005)


def _setup(plan: AnyPlan, speed_dps: float = 3600.0) -> tuple[MemRig, JobStore, ScanEngine]:
    rig = MemRig(speed_dps)
    desc = RigDescription.from_rig(rig)
    store = JobStore(":memory:")
    job = store.create_job(kind=plan.kind, specimen="s", plan=plan.model_dump(mode="json"),
                           rig=desc.model_dump(mode="json"))
    return rig, store, ScanEngine(rig, store, job.id, plan, desc)


def _states(store: JobStore) -> list[str]:
    return [e.data["state"] for e in store.events_after(0) if e.type in ("created", "state")]


async def _until(cond: Callable[[], bool], timeout: float = 5.0) -> None:
    t = 0.0
    while not cond():
        await asyncio.sleep(0.002)
        t += 0.002
        assert t < timeout, "condition not reached"


def test_uniform_scan_sequence_and_checkpoints() -> None:
    plan = UniformPlan(rotations=4, exposure=FAST)
    rig, store, eng = _setup(plan)
    assert asyncio.run(eng.run()) is JobState.RUNNING
    assert store.reading_count(1) == 4 * 3
    assert [s.done for s in store.steps(1)] == [True] * 4
    # One light at a time; every read happens while exactly its light is on.
    on: set[str] = set()
    for dev, what, _ in rig.log.calls:
        if what == "on":
            assert not on
            on.add(dev)
        elif what == "off":
            on.discard(dev)
    assert not rig.any_light_on()
    # S1 is read for both lights (in parallel with S2 under L1), plus one dark.
    assert rig.sensor("S1").reads == 4 * 2 + 1
    assert rig.sensor("S2").reads == 4 + 1
    assert rig.mstage.moves == [0.0, 45.0, 90.0, 135.0]  # half a turn: k 180 / 4
    events = [e.type for e in store.events_after(0)]
    assert events.count("progress") == 4
    rows = store.readings(1)
    assert all(r.dark == (0.01, 0.01, 0.01) for r in rows)


def test_pause_at_checkpoint_and_resume() -> None:
    plan = UniformPlan(rotations=6, exposure=FAST)
    rig, store, eng = _setup(plan, speed_dps=900.0)

    async def go() -> JobState:
        task = asyncio.create_task(eng.run())
        await _until(lambda: store.get_job(1).done_angles >= 1)
        eng.request_pause()
        await _until(lambda: eng.state is JobState.PAUSED)
        done = store.get_job(1).done_angles
        await asyncio.sleep(0.05)
        assert store.get_job(1).done_angles == done  # nothing measured while paused
        assert not rig.any_light_on()
        eng.request_resume()
        return await task

    assert asyncio.run(go()) is JobState.RUNNING
    assert store.reading_count(1) == 6 * 3
    assert _states(store) == ["queued", "running", "paused", "running"]


def test_immediate_pause_repeats_the_interrupted_angle_without_duplicates() -> None:
    plan = UniformPlan(rotations=4, exposure=ExposureSettings(exposure_s=0.05, light_settle_s=0))
    rig, store, eng = _setup(plan)

    async def go() -> JobState:
        task = asyncio.create_task(eng.run())
        await _until(lambda: rig.any_light_on())
        eng.request_pause(immediate=True)
        await _until(lambda: eng.state is JobState.PAUSED)
        assert store.reading_count(1) == 0  # the interrupted angle was not committed
        assert not rig.any_light_on()
        eng.request_resume()
        return await task

    assert asyncio.run(go()) is JobState.RUNNING
    rows = store.readings(1)
    assert len(rows) == 12
    assert len({(r.angle_index, r.light, r.sensor) for r in rows}) == 12
    assert rig.mstage.moves.count(0.0) == 2  # the first angle was visited twice


@pytest.mark.parametrize("halt", [False, True])
def test_abort_cleans_up_and_halt_does_not(halt: bool) -> None:
    plan = UniformPlan(rotations=4, exposure=ExposureSettings(exposure_s=0.05, light_settle_s=0))
    rig, store, eng = _setup(plan)

    async def go() -> JobState:
        task = asyncio.create_task(eng.run())
        await _until(lambda: rig.any_light_on())
        stops = rig.mstage.stopped
        calls = len(rig.log.calls)
        (eng.request_halt if halt else eng.request_abort)()
        final = await task
        if halt:
            # Nothing but the interrupted light's own switch-off reaches the devices.
            assert rig.mstage.stopped == stops
            assert all(w in ("off",) for _, w, _ in rig.log.calls[calls:])
        else:
            assert rig.mstage.stopped == stops + 1
        return final

    final = asyncio.run(go())
    assert final is (JobState.HALTED if halt else JobState.ABORTED)
    assert store.get_job(1).state is final


def test_stage_fault_suspends_clears_and_resumes() -> None:
    plan = UniformPlan(rotations=3, exposure=FAST, faults=QUICK_FAULTS)
    rig, store, eng = _setup(plan)
    rig.mstage.fault_next_moves = [hal.StageFault("stage", "overload", code="overload")]
    assert asyncio.run(eng.run()) is JobState.RUNNING
    assert _states(store) == ["queued", "running", "suspended", "running"]
    assert ("stage", "clear_faults", None) in rig.log.calls
    assert store.reading_count(1) == 9
    assert store.get_job(1).reason is None


def test_lost_light_is_reconnected() -> None:
    plan = UniformPlan(rotations=2, exposure=FAST, faults=QUICK_FAULTS)
    rig, store, eng = _setup(plan)
    rig.light("L2").unavailable = 1
    assert asyncio.run(eng.run()) is JobState.RUNNING
    assert ("L2", "connect", None) in rig.log.calls
    assert store.reading_count(1) == 6
    codes = [e.data.get("code") for e in store.events_after(0)
             if e.data.get("state") == "suspended"]
    assert codes == ["timeout"]


def test_lamp_out_of_band_suspends_until_it_recovers() -> None:
    plan = UniformPlan(rotations=2, exposure=FAST, faults=QUICK_FAULTS.model_copy(
        update={"max_retries": 50}))
    rig, store, eng = _setup(plan)

    async def go() -> JobState:
        rig.light("L1").in_band = False
        task = asyncio.create_task(eng.run())
        await _until(lambda: eng.state is JobState.SUSPENDED)
        await asyncio.sleep(0.03)
        assert store.reading_count(1) == 0 and eng.state is JobState.SUSPENDED
        rig.light("L1").in_band = True
        return await task

    assert asyncio.run(go()) is JobState.RUNNING
    assert store.reading_count(1) == 6
    job_events = store.events_after(0)
    assert any(e.data.get("code") == "out_of_band" for e in job_events)


def test_permanent_fault_fails_with_reason_and_lights_off() -> None:
    plan = UniformPlan(rotations=3, exposure=FAST, faults=QUICK_FAULTS)
    rig, store, eng = _setup(plan)
    rig.mstage.fault_next_moves = [hal.StageFault("stage", "overload", code="overload")]
    rig.mstage.sticky_fault = True
    assert asyncio.run(eng.run()) is JobState.FAILED
    job = store.get_job(1)
    assert "persisted after 3 retries" in (job.reason or "")
    assert "overload" in (job.reason or "")
    assert not rig.any_light_on()
    assert rig.mstage.stopped >= 1


def test_unrecoverable_fault_fails_at_once() -> None:
    plan = UniformPlan(rotations=3, exposure=FAST, faults=QUICK_FAULTS)
    rig, store, eng = _setup(plan)
    rig.mstage.fault_next_moves = [
        hal.StageFault("stage", "encoder broken", code="encoder", recoverable=False)]
    assert asyncio.run(eng.run()) is JobState.FAILED
    assert "unrecoverable" in (store.get_job(1).reason or "")
    assert "suspended" not in _states(store)


def test_saturation_suspends_then_retries() -> None:
    plan = UniformPlan(rotations=2, exposure=FAST, faults=QUICK_FAULTS)
    rig, store, eng = _setup(plan)
    rig.sensor("S2").saturate_next = 1
    assert asyncio.run(eng.run()) is JobState.RUNNING
    assert not any(r.saturated for r in store.readings(1))
    rig2, store2, eng2 = _setup(plan.model_copy(update={"faults": QUICK_FAULTS.model_copy(
        update={"saturation": "record"})}))
    rig2.sensor("S2").saturate_next = 1
    assert asyncio.run(eng2.run()) is JobState.RUNNING
    assert sum(r.saturated for r in store2.readings(1)) == 1


def test_restart_resumes_from_checkpoint() -> None:
    """A second engine on the same store measures only what the first did not commit."""
    plan = UniformPlan(rotations=5, exposure=ExposureSettings(exposure_s=0.01, light_settle_s=0))
    rig, store, eng = _setup(plan)

    async def first() -> None:
        task = asyncio.create_task(eng.run())
        await _until(lambda: store.get_job(1).done_angles >= 2)
        task.cancel()  # the process dies: the job stays active in the store
        with pytest.raises(asyncio.CancelledError):
            await task

    asyncio.run(first())
    done = store.get_job(1).done_angles
    assert store.get_job(1).state is JobState.RUNNING
    eng2 = ScanEngine(rig, store, 1, plan, RigDescription.from_rig(rig))
    before = len(rig.mstage.moves)
    assert asyncio.run(eng2.run()) is JobState.RUNNING
    assert len(rig.mstage.moves) - before == 5 - done
    rows = store.readings(1)
    assert len(rows) == 15 and len({(r.angle_index, r.light, r.sensor) for r in rows}) == 15


@pytest.mark.parametrize(("homed_at_start", "loses_zero", "fails"), [
    (True, True, True), (True, False, False), (False, True, False)])
def test_a_job_resumed_on_a_stage_that_lost_its_zero_fails_saying_so(
        homed_at_start: bool, loses_zero: bool, fails: bool) -> None:
    """The daemon (and the rig with it) restarted mid-job: a stage homed when the job began
    that now reads not homed, on a stage whose zero a power cycle moves, would read at other
    angles than the job's; the resumed job fails, its angles kept. A direct-drive servo (its
    zero survives) or a job that began unhomed (no zero to lose) goes on."""
    plan = UniformPlan(rotations=5, exposure=ExposureSettings(exposure_s=0.01, light_settle_s=0))
    rig, store, eng = _setup(plan)
    rig.mstage.homed = homed_at_start

    async def first() -> None:
        task = asyncio.create_task(eng.run())
        await _until(lambda: store.get_job(1).done_angles >= 2)
        task.cancel()
        with pytest.raises(asyncio.CancelledError):
            await task

    asyncio.run(first())
    done = store.get_job(1).done_angles
    rig.mstage.homed, rig.mstage.zero_lost_at_power_up = False, loses_zero  # powered off, on
    state = asyncio.run(ScanEngine(rig, store, 1, plan, RigDescription.from_rig(rig)).run())
    if not fails:
        assert state is JobState.RUNNING and store.get_job(1).done_angles == 5
        return
    assert state is JobState.FAILED
    reason = store.get_job(1).reason or ""
    assert reason.startswith("the stage lost its zero during the job"), reason
    assert f"The readings of the {done} angles measured before stay in the job store" in reason, \
        reason
    assert store.get_job(1).done_angles == done
    assert len(store.readings(1)) == 3 * done


def test_a_pause_asked_during_the_last_angle_does_not_hold_a_measured_job() -> None:
    """A pause asked (and kept, a pause_asked event) in a uniform job's last angle, the
    daemon stopped before it began finishing: nothing is left to measure, so the job goes on
    to finish, as the pause's answer says, instead of coming back paused with no angle."""
    plan = UniformPlan(rotations=3, exposure=FAST)
    rig, store, eng = _setup(plan)
    assert asyncio.run(eng.run()) is JobState.RUNNING  # measured; finishing is next
    store.append_event(1, "pause_asked", {"immediate": False})
    again = ScanEngine(rig, store, 1, plan, RigDescription.from_rig(rig))
    assert asyncio.run(asyncio.wait_for(again.run(), 30)) is JobState.RUNNING
    assert store.get_job(1).done_angles == 3


def test_adaptive_adds_rounds_until_converged() -> None:
    plan = AdaptivePlan(rule="vf", initial_rotations=8, threshold=0.01, exposure=FAST,
                        max_rounds=3)
    _, store, eng = _setup(plan)
    assert asyncio.run(eng.run()) is JobState.RUNNING
    steps = store.steps(1)
    assert {s.round for s in steps} == {0, 1, 2}
    assert len({round(s.specimen_deg, 6) for s in steps}) == len(steps)
    budget = AdaptivePlan(rule="vf", initial_rotations=8, threshold=0.01, exposure=FAST,
                          max_samples=36)
    _rig, store, eng = _setup(budget)
    asyncio.run(eng.run())
    assert len(store.steps(1)) * 3 <= 36


def test_saturation_in_a_sensors_only_range_fails_naming_gain_stages() -> None:
    plan = UniformPlan(rotations=2, exposure=FAST, faults=QUICK_FAULTS)
    rig, store, eng = _setup(plan)
    rig.sensor("S2").saturate_next = 100  # every lit reading of S2, at every retry
    assert asyncio.run(eng.run()) is JobState.FAILED
    reason = store.get_job(1).reason or ""
    assert "S2: saturated in its only range" in reason and "gain_stages" in reason


class CountingStore(JobStore):
    """The real SQLite store, counting how often the engine reads steps and readings."""

    def __init__(self, path: str) -> None:
        super().__init__(path)
        self.reads = {"steps": 0, "readings": 0}

    def steps(self, job_id: int) -> list[StepRow]:
        self.reads["steps"] += 1
        return super().steps(job_id)

    def readings(self, job_id: int) -> list[ReadingRow]:
        self.reads["readings"] += 1
        return super().readings(job_id)


def _adaptive(store: JobStore, plan: AdaptivePlan) -> tuple[MemRig, ScanEngine]:
    rig = MemRig(3600.0)
    desc = RigDescription.from_rig(rig)
    job = store.create_job(kind=plan.kind, specimen="s", plan=plan.model_dump(mode="json"),
                           rig=desc.model_dump(mode="json"))
    return rig, ScanEngine(rig, store, job.id, plan, desc)


VF3 = AdaptivePlan(rule="vf", initial_rotations=8, threshold=0.01, exposure=FAST, max_rounds=3)


def test_the_engine_keeps_its_readings_beside_the_store() -> None:
    """An adaptive job of three rounds reads its steps from the store once (at its start)
    and its readings never (it has none yet): the rounds are planned from the readings the
    engine wrote, which are exactly those the store holds."""
    store = CountingStore(":memory:")
    _rig, eng = _adaptive(store, VF3)
    assert asyncio.run(eng.run()) is JobState.RUNNING
    assert store.reads == {"steps": 1, "readings": 0}
    steps = JobStore.steps(store, 1)
    assert {s.round for s in steps} == {0, 1, 2}
    angles, values = eng.measured_values(steps)
    rows = JobStore.readings(store, 1)
    assert angles == [s.specimen_deg for s in steps]
    np.testing.assert_array_equal(
        values, readings_array(rows, eng.pairs, [s.angle_index for s in steps], len(rows[0].raw)))


def test_an_adaptive_job_resumed_mid_round_plans_as_one_that_was_not() -> None:
    """Killed during its second round, an adaptive job resumes from the store (read once)
    and ends with the same steps, each reading once, as the job run in one go."""
    whole = JobStore(":memory:")
    _rig, eng = _adaptive(whole, VF3)
    asyncio.run(eng.run())
    want = [(s.angle_index, s.round, s.specimen_deg) for s in whole.steps(1)]
    store = CountingStore(":memory:")
    rig, eng = _adaptive(store, VF3)

    async def first() -> None:
        task = asyncio.create_task(eng.run())
        await _until(lambda: store.get_job(1).done_angles >= 10)
        task.cancel()  # the process dies: the job stays active in the store
        with pytest.raises(asyncio.CancelledError):
            await task

    asyncio.run(first())
    assert any(s.round == 1 and not s.done for s in JobStore.steps(store, 1))
    store.reads = {"steps": 0, "readings": 0}
    eng2 = ScanEngine(rig, store, 1, VF3, RigDescription.from_rig(rig))
    assert asyncio.run(eng2.run()) is JobState.RUNNING
    assert store.reads == {"steps": 1, "readings": 1}
    assert [(s.angle_index, s.round, s.specimen_deg) for s in JobStore.steps(store, 1)] == want
    rows = JobStore.readings(store, 1)
    keys = [(r.angle_index, r.light, r.sensor) for r in rows]
    assert len(keys) == len(set(keys)) == 3 * len(want)
