"""Manual stage commands through :class:`gonio.stage_control.StageControl`, on the in-memory rig.

The queue it holds is a real :class:`gonio.worker.Worker` over a real (in-memory) job store, so
what is asserted is what the store records: the hold around the command, its release, and a
hold that was there before (a halt) left alone.
"""

from __future__ import annotations

import asyncio
from pathlib import Path

import pytest

from gonio.basis_supply import BasisSupply
from gonio.motion import StageMoveError
from gonio.rigdescription import RigDescription
from gonio.service_models import Conflict, JobInfo, StageRequest, StageState
from gonio.sim.memrig import MemRig
from gonio.stage_control import StageControl
from gonio.store import JobStore
from gonio.worker import Worker


def _control(tmp_path: Path, active: JobInfo | None = None
             ) -> tuple[StageControl, Worker, JobStore, MemRig]:
    rig = MemRig()
    desc = RigDescription.from_rig(rig)
    store = JobStore(":memory:")

    async def get_rig() -> MemRig:
        return rig

    worker = Worker(store, get_rig, desc, tmp_path, BasisSupply(lambda: pytest.fail("no basis")))

    def record(type_: str, data: dict[str, object]) -> object:
        return store.append_event(None, type_, data)

    control = StageControl(desc, get_rig, worker, lambda: active, record)  # type: ignore[arg-type]
    return control, worker, store, rig


def test_a_move_holds_the_queue_for_its_duration_only(tmp_path: Path) -> None:
    control, worker, store, rig = _control(tmp_path)
    state = asyncio.run(control.command(StageRequest(action="move", angle_deg=40.0)))
    assert state.position_deg == pytest.approx(40.0, abs=0.2)
    assert rig.mstage.pos == pytest.approx(40.0, abs=0.2)
    events = [(e.type, e.data) for e in store.events_after(0)]
    assert [t for t, _ in events] == ["queue_held", "queue_released", "stage"]
    assert events[0][1]["reason"] == "manual stage command: move"
    assert events[2][1]["position_deg"] == pytest.approx(40.0, abs=0.2)
    assert worker.held is None and store.hold("queue") is None  # not durable: nothing left


def test_a_queue_held_before_stays_held(tmp_path: Path) -> None:
    control, worker, store, _ = _control(tmp_path)
    worker.hold("emergency halt")
    asyncio.run(control.command(StageRequest(action="home")))
    assert worker.held == "emergency halt"
    assert "queue_released" not in [e.type for e in store.events_after(0)]


def test_refused_while_a_job_is_active_but_stop_is_always_accepted(tmp_path: Path) -> None:
    store = JobStore(":memory:")
    row = store.create_job(kind="uniform", specimen="s", plan={}, rig={})
    control, _, _, rig = _control(tmp_path, active=JobInfo.from_row(row))
    with pytest.raises(Conflict, match=f"job {row.id} is queued"):
        asyncio.run(control.command(StageRequest(action="move", angle_deg=10.0)))
    assert rig.mstage.moves == []
    asyncio.run(control.command(StageRequest(action="stop")))


@pytest.mark.parametrize(("states", "says", "never"), [
    # Paused: it said "pause or abort it" to a paused job, whose stage stays refused.
    (("running", "paused"), "is paused: it still holds the stage", "or pause"),
    # Reconstructing: a job that cannot be paused, whose stage does not move any more.
    (("running", "reconstructing"), "is reconstructing: it moves the stage no more", "pause"),
    (("running",), "is running: the stage is in use; wait for the job to end, or abort it",
     "or pause"),
])
def test_a_refusal_says_what_frees_the_stage(tmp_path: Path, states: tuple[str, ...],
                                             says: str, never: str) -> None:
    from gonio.jobstates import JobState

    store = JobStore(":memory:")
    row = store.create_job(kind="uniform", specimen="s", plan={}, rig={})
    for state in states:
        row = store.set_state(row.id, JobState(state))
    control, _, _, rig = _control(tmp_path, active=JobInfo.from_row(row))
    with pytest.raises(Conflict) as refused:
        asyncio.run(control.command(StageRequest(action="move", angle_deg=10.0)))
    assert says in str(refused.value) and never not in str(refused.value), refused.value
    assert rig.mstage.moves == []


def test_a_move_outside_the_travel_limits_says_them(tmp_path: Path) -> None:
    control, _, store, rig = _control(tmp_path)
    lo, hi = control.desc.stage_min_deg, control.desc.stage_max_deg
    with pytest.raises(StageMoveError, match=f"\\[{lo:g}, {hi:g}\\]"):
        asyncio.run(control.command(StageRequest(action="move", angle_deg=hi + 1.0)))
    with pytest.raises(StageMoveError, match="needs angle_deg"):
        asyncio.run(control.command(StageRequest(action="move")))
    assert rig.mstage.moves == [] and store.events_after(0) == []


def test_a_move_cut_short_by_stop_ends_as_asked_not_as_a_fault(tmp_path: Path) -> None:
    """Stop pressed during a manual move: the driver reports a stage stopped short of its
    target as a stall ("check for a mechanical obstruction"), and the move answered 503,
    "moving to -350 refused". A stop asked meanwhile makes it an answer, saying where the
    stage stopped; a stall with no stop asked is still a fault."""
    from gonio import hal
    from gonio.service_models import DeviceError

    control, worker, _, rig = _control(tmp_path)
    stage = rig.mstage
    stopped = asyncio.Event()

    async def move_to(angle_deg: float, timeout_s: float | None = None) -> float:
        # As a servo does: it turns until stopped, then stands short of its target.
        stage.pos = 12.5
        await stopped.wait()
        raise hal.StageFault("stage", f"stage stopped at {stage.pos} deg, short of the target "
                             f"{angle_deg} deg; check for a mechanical obstruction")

    async def stop() -> None:
        stopped.set()

    stage.move_to = move_to  # type: ignore[method-assign]
    stage.stop = stop  # type: ignore[method-assign]

    async def go() -> tuple[StageState, StageState]:
        move = asyncio.create_task(control.command(StageRequest(action="move", angle_deg=-350)))
        await asyncio.sleep(0.05)
        halt = await control.command(StageRequest(action="stop"))
        return await move, halt

    moved, _ = asyncio.run(go())
    assert moved.note == ("stopped by a stop command before it ended: at 12.500 deg, short of "
                          "-350 deg")
    assert moved.position_deg == 12.5
    assert worker.held is None
    # A stall nobody asked for is a fault, as before.
    stopped.set()
    with pytest.raises(DeviceError, match="check for a mechanical obstruction"):
        asyncio.run(control.command(StageRequest(action="move", angle_deg=40.0)))
