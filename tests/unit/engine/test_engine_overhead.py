"""The engine spends no device round trips it does not need, without giving up its checks.

Each test arms one device of the in-memory rig to record when it is asked something, and checks
the order of events against what the measurement needs: the lamp is checked while its sensors
integrate, the stage position is read only when a backlash overshoot may follow, and a lamp
found out of band during the exposure still discards the angle.
"""

from __future__ import annotations

import asyncio

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
