"""The engine spends no device round trips it does not need, without giving up its checks.

Each test arms one device of the in-memory rig (or the store) to record when it is asked
something, and checks the order of events against what the measurement needs: the lamp is
checked while its sensors integrate, the stage position is read only when a backlash overshoot
may follow, a lamp found out of band during the exposure still discards the angle, the lamps
are switched and the checkpoint written while the stage moves on, a dark is written while the
lamps work and before the checkpoint, the planned steps before the first move, and a
checkpoint or a dark that cannot be written fails the job keeping what was stored.
"""

from __future__ import annotations

import asyncio
import contextlib
import sqlite3
import time
from typing import Any

import pytest

from gonio import hal
from gonio.engine import ScanEngine
from gonio.jobstates import JobState
from gonio.plans.models import ExposureSettings, FaultPolicy, UniformPlan
from gonio.rigdescription import RigDescription
from gonio.sim.memrig import Log, MemLight, MemRig, MemStage
from gonio.store import JobStore

EXPOSURE = ExposureSettings(exposure_s=0.02, light_settle_s=0.0, dark="none")
QUICK_FAULTS = FaultPolicy(max_retries=3, retry_delay_s=0.005, resume_settle_s=0.005)


class CountingStage(MemStage):
    """Counts :meth:`position` reads (a round trip on a real stage)."""

    def __init__(self, log: Log) -> None:
        super().__init__(log)
        self.position_reads = 0

    async def position(self) -> float:
        self.position_reads += 1
        return await super().position()


class WatchedLight(MemLight):
    """Logs its status checks; ``out_of_band_checks`` of them report the lamp out of band."""

    def __init__(self, base: MemLight, log: Log) -> None:
        super().__init__(base.name, log, base.direction.theta_deg, base.direction.phi_deg)
        self.out_of_band_checks = 0

    async def status(self) -> hal.LightStatus:
        self.log.add(self.name, "status")
        if self.out_of_band_checks > 0:
            self.out_of_band_checks -= 1
            return hal.LightStatus(self.on, 1.0, in_band=False, faults=("out_of_band",))
        return hal.LightStatus(self.on, 1.0, True)


def _rig(stage: bool = False) -> MemRig:
    rig = MemRig()
    rig.lights = {n: WatchedLight(rig.light(n), rig.log) for n in rig.lights}
    if stage:
        rig.stage = CountingStage(rig.log)
    return rig


def _engine(rig: MemRig, plan: UniformPlan) -> tuple[JobStore, ScanEngine]:
    desc = RigDescription.from_rig(rig)
    store = JobStore(":memory:")
    job = store.create_job(kind=plan.kind, specimen="s", plan=plan.model_dump(mode="json"),
                           rig=desc.model_dump(mode="json"))
    return store, ScanEngine(rig, store, job.id, plan, desc)


def test_lamp_is_checked_while_its_sensors_integrate() -> None:
    rig = _rig()
    store, eng = _engine(rig, UniformPlan(rotations=3, exposure=EXPOSURE))
    assert asyncio.run(eng.run()) is JobState.RUNNING
    assert store.reading_count(1) == 3 * 3
    # Per light period: on, every sensor read started, the status check, then off; the
    # status check comes after the reads were started, so it waits behind their triggers.
    period: list[tuple[str, str]] = []
    periods = []
    for dev, what, _ in rig.log.calls:
        if what in ("on", "read", "status", "off"):
            period.append((dev, what))
        if what == "off":
            if period[0][1] == "on":  # not the final all-lights-off cleanup
                periods.append(period)
            period = []
    assert len(periods) == 3 * 2
    for p in periods:
        light = p[0][0]
        assert p[0] == (light, "on") and p[-1] == (light, "off")
        middle = [w for _, w in p[1:-1]]
        assert middle.count("status") == 1
        assert middle[-1] == "status" and set(middle[:-1]) == {"read"}


def test_lamp_out_of_band_during_the_exposure_discards_the_angle() -> None:
    rig = _rig()
    lamp = rig.lights["L2"]
    assert isinstance(lamp, WatchedLight)
    lamp.out_of_band_checks = 1
    plan = UniformPlan(rotations=2, exposure=EXPOSURE, faults=QUICK_FAULTS)
    store, eng = _engine(rig, plan)
    assert asyncio.run(eng.run()) is JobState.RUNNING
    suspended = [e.data for e in store.events_after(0)
                 if e.type == "state" and e.data["state"] == "suspended"]
    assert len(suspended) == 1
    assert (suspended[0]["device"], suspended[0]["code"]) == ("L2", "out_of_band")
    # The angle was measured again: every pair once per angle, nothing from the bad period.
    rows = store.readings(1)
    assert len(rows) == 2 * 3
    assert len({(r.angle_index, r.light, r.sensor) for r in rows}) == len(rows)
    assert not rig.any_light_on()


def test_stage_position_is_not_read_per_angle_without_backlash_overshoot() -> None:
    rig = _rig(stage=True)
    stage = rig.stage
    assert isinstance(stage, CountingStage)
    store, eng = _engine(rig, UniformPlan(rotations=6, exposure=EXPOSURE, backlash_deg=0.0))
    assert asyncio.run(eng.run()) is JobState.RUNNING
    assert store.reading_count(1) == 6 * 3
    assert stage.position_reads == 1  # once, to plan the route


def test_stage_position_is_read_per_angle_when_an_overshoot_may_be_needed() -> None:
    rig = _rig(stage=True)
    stage = rig.stage
    assert isinstance(stage, CountingStage)
    stage.pos = 100.0  # the route starts below: the first move must overshoot from above
    _, eng = _engine(rig, UniformPlan(rotations=4, exposure=EXPOSURE, backlash_deg=2.0))
    assert asyncio.run(eng.run()) is JobState.RUNNING
    assert stage.position_reads == 1 + 4
    first, *rest = stage.moves
    assert first < stage.moves[1] and first == stage.moves[1] - 2.0  # approached from below
    assert rest == sorted(rest)


class LampWatchingStage(MemStage):
    """A stage whose every move lasts until light ``L1`` is on (or 5 s, when nothing switches
    it meanwhile) and records the device calls made while it moved."""

    def __init__(self, log: Log, lights: dict[str, hal.Light]) -> None:
        super().__init__(log)
        self.lights = lights
        self.during: list[list[tuple[str, str]]] = []

    async def move_to(self, angle_deg: float, timeout_s: float | None = None) -> float:
        start = len(self.log.calls)
        first = self.lights["L1"]
        assert isinstance(first, MemLight)
        with contextlib.suppress(TimeoutError):
            async with asyncio.timeout(5.0):
                while not first.on:
                    await asyncio.sleep(0.001)
        pos = await super().move_to(angle_deg, timeout_s)
        self.during.append([(dev, what) for dev, what, _ in self.log.calls[start:]])
        return pos


class SlowToSwitchOff(MemLight):
    """A light whose switching off is acknowledged after 5 ms (a request on a real link)."""

    async def set_on(self, on: bool) -> None:
        if not on:
            await asyncio.sleep(0.005)
        await super().set_on(on)


def test_lamps_are_switched_while_the_stage_moves() -> None:
    rig = MemRig()
    rig.lights["L2"] = SlowToSwitchOff("L2", rig.log, 30.0, 90.0)
    stage = LampWatchingStage(rig.log, rig.lights)
    rig.stage = stage
    store, eng = _engine(rig, UniformPlan(rotations=3, exposure=EXPOSURE))
    assert asyncio.run(eng.run()) is JobState.RUNNING
    assert store.reading_count(1) == 3 * 3
    # No dark to read: the first light goes on during each move, and from the second move
    # on the previous angle's last light goes off first; nothing is read while it moves.
    assert [[c for c in d if c[1] in ("on", "off", "read")] for d in stage.during] == [
        [("L1", "on")],
        [("L2", "off"), ("L1", "on")],
        [("L2", "off"), ("L1", "on")],
    ]
    assert not rig.any_light_on()


def test_a_dark_is_read_with_every_lamp_off_after_the_move() -> None:
    rig = MemRig()
    plan = UniformPlan(rotations=2, exposure=ExposureSettings(
        exposure_s=0.02, light_settle_s=0.0, dark="every_angle"))
    store, eng = _engine(rig, plan)
    assert asyncio.run(eng.run()) is JobState.RUNNING
    # Each angle: move, then the darks with every lamp off, then the lights.
    lit: set[str] = set()
    darks_read = 0
    for dev, what, _ in rig.log.calls:
        if what == "on":
            lit.add(dev)
        elif what == "off":
            lit.discard(dev)
        elif what == "read" and not lit:
            darks_read += 1
        elif what == "move":
            darks_read = 0
        assert len(lit) <= 1
    assert len(store.darks(1)) == 2
    rows = store.readings(1)
    assert all(r.dark == (0.01, 0.01, 0.01) for r in rows)  # MemSensor's dark level


class BesideTheMoveStore(JobStore):
    """A store whose angle checkpoint waits (up to 5 s) until the stage has started the move
    after it, and notes whether it had; the last angle's does not wait."""

    def __init__(self, stage: MemStage, angles: int) -> None:
        super().__init__(":memory:")
        self.stage = stage
        self.angles = angles
        self.beside_next_move: list[bool] = []

    def commit_angle(self, job_id: int, angle_index: int, *args: Any, **kwargs: Any) -> Any:
        if angle_index < self.angles - 1:
            deadline = time.monotonic() + 5.0
            while (sum(1 for c in self.stage.log.calls if c[1] == "move") <= angle_index + 1
                   and time.monotonic() < deadline):
                time.sleep(0.001)
            moves = sum(1 for c in self.stage.log.calls if c[1] == "move")
            self.beside_next_move.append(moves > angle_index + 1)
        return super().commit_angle(job_id, angle_index, *args, **kwargs)


def test_the_checkpoint_is_written_while_the_stage_moves_on_and_before_what_follows() -> None:
    rig = MemRig()
    plan = UniformPlan(rotations=4, exposure=EXPOSURE)
    desc = RigDescription.from_rig(rig)
    store = BesideTheMoveStore(rig.mstage, 4)
    job = store.create_job(kind=plan.kind, specimen="s", plan=plan.model_dump(mode="json"),
                           rig=desc.model_dump(mode="json"))
    eng = ScanEngine(rig, store, job.id, plan, desc)
    assert asyncio.run(eng.run()) is JobState.RUNNING
    assert store.beside_next_move == [True, True, True]
    # Every checkpoint is stored by the time the engine returns, in order, and the progress
    # the engine reports is the last stored one.
    assert [s.done for s in store.steps(1)] == [True] * 4
    assert store.reading_count(1) == 4 * 3
    done = [e.data["done"] for e in store.events_after(0) if e.type == "progress"]
    assert done == [1, 2, 3, 4]
    assert eng.progress.done == 4


def _fill_the_disk() -> None:
    """Raise what SQLite raises on a full disk (SQLITE_FULL)."""
    tiny = sqlite3.connect(":memory:")
    tiny.execute("CREATE TABLE t (x BLOB)")
    tiny.execute("PRAGMA max_page_count = 2")
    tiny.execute("INSERT INTO t VALUES (zeroblob(100000))")


def _fails_for_a_full_disk(rig: MemRig, plan: UniformPlan, store: JobStore) -> None:
    """Run ``plan`` on ``rig`` into ``store``: the job fails, saying the disk is full."""
    desc = RigDescription.from_rig(rig)
    job = store.create_job(kind=plan.kind, specimen="s", plan=plan.model_dump(mode="json"),
                           rig=desc.model_dump(mode="json"))
    with pytest.raises(sqlite3.OperationalError):
        asyncio.run(ScanEngine(rig, store, job.id, plan, desc).run())
    got = store.get_job(job.id)
    assert got.state == JobState.FAILED.value
    assert got.reason is not None and got.reason.startswith("disk full: ")


class FullAtStore(JobStore):
    """A store whose checkpoint of angle ``full_at`` fails as SQLite does on a full disk."""

    def __init__(self, full_at: int) -> None:
        super().__init__(":memory:")
        self.full_at = full_at

    def commit_angle(self, job_id: int, angle_index: int, *args: Any, **kwargs: Any) -> Any:
        if angle_index == self.full_at:
            _fill_the_disk()
        return super().commit_angle(job_id, angle_index, *args, **kwargs)


def test_a_checkpoint_refused_for_a_full_disk_fails_the_job_keeping_what_was_stored() -> None:
    rig = MemRig()
    store = FullAtStore(full_at=1)
    _fails_for_a_full_disk(rig, UniformPlan(rotations=4, exposure=EXPOSURE), store)
    # Angle 0 stays stored; angle 1 was never reported; the lamps are off, the stage stopped.
    assert [s.done for s in store.steps(1)] == [True, False, False, False]
    assert store.reading_count(1) == 3
    assert [e.data["done"] for e in store.events_after(0) if e.type == "progress"] == [1]
    assert not rig.any_light_on() and rig.mstage.stopped >= 1


def _wait_for(log: Log, seen: Any, limit_s: float = 5.0) -> bool:
    """Block (a store's worker thread) until ``seen(log.calls)`` holds or ``limit_s`` passed;
    whether it held."""
    deadline = time.monotonic() + limit_s
    while not seen(log.calls) and time.monotonic() < deadline:
        time.sleep(0.001)
    return bool(seen(log.calls))


class BesideTheLampsStore(JobStore):
    """A store whose dark waits (up to 5 s) until a lamp was switched on after it was read,
    noting whether one had; it notes the stage moves made before the steps were planned, and
    in what order the writes came."""

    def __init__(self, log: Log) -> None:
        super().__init__(":memory:")
        self.log = log
        self.moves_before_steps: list[int] = []
        self.dark_beside_lamp: list[bool] = []
        self.order: list[str] = []

    def add_steps(self, job_id: int, steps: Any) -> None:
        self.moves_before_steps.append(sum(1 for c in self.log.calls if c[1] == "move"))
        self.order.append("steps")
        super().add_steps(job_id, steps)

    def add_darks(self, job_id: int, angle_index: int, darks: Any) -> None:
        ons = sum(1 for c in self.log.calls if c[1] == "on")
        self.dark_beside_lamp.append(_wait_for(
            self.log, lambda calls: sum(1 for c in calls if c[1] == "on") > ons))
        self.order.append("dark")
        super().add_darks(job_id, angle_index, darks)

    def commit_angle(self, job_id: int, angle_index: int, *args: Any, **kwargs: Any) -> Any:
        self.order.append(f"angle {angle_index}")
        return super().commit_angle(job_id, angle_index, *args, **kwargs)


def test_the_dark_is_written_beside_the_lamps_and_in_order() -> None:
    rig = MemRig()
    plan = UniformPlan(rotations=3, exposure=ExposureSettings(
        exposure_s=0.02, light_settle_s=0.0, dark="once"))
    desc = RigDescription.from_rig(rig)
    store = BesideTheLampsStore(rig.log)
    job = store.create_job(kind=plan.kind, specimen="s", plan=plan.model_dump(mode="json"),
                           rig=desc.model_dump(mode="json"))
    assert asyncio.run(ScanEngine(rig, store, job.id, plan, desc).run()) is JobState.RUNNING
    # The steps were stored before anything moved (their "planned" event is the last word
    # before a move), the dark while the first lamp was on, each before the checkpoint.
    assert store.moves_before_steps == [0]
    assert store.dark_beside_lamp == [True]
    assert store.order == ["steps", "dark", "angle 0", "angle 1", "angle 2"]
    assert [s.done for s in store.steps(1)] == [True] * 3
    assert list(store.darks(1)) == [0]
    types = [e.type for e in store.events_after(0)]
    assert types.index("planned") < types.index("progress")


class DarkFullStore(JobStore):
    """A store whose dark fails as SQLite does on a full disk."""

    def add_darks(self, job_id: int, angle_index: int, darks: Any) -> None:
        _fill_the_disk()


def test_a_dark_refused_for_a_full_disk_fails_the_job_before_any_checkpoint() -> None:
    rig = MemRig()
    store = DarkFullStore(":memory:")
    _fails_for_a_full_disk(rig, UniformPlan(rotations=3, exposure=ExposureSettings(
        exposure_s=0.02, light_settle_s=0.0, dark="once")), store)
    # The planned steps stay; no reading of the angle whose dark was lost was reported.
    assert [s.done for s in store.steps(1)] == [False] * 3
    assert store.reading_count(1) == 0
    assert not [e for e in store.events_after(0) if e.type == "progress"]
    assert not rig.any_light_on() and rig.mstage.stopped >= 1
