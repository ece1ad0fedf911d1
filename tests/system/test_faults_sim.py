"""Honest fault reports and patience, on the simulated rig over the real protocols.

* A silent sensor on a Modbus link it shares with the others is the one the job blames (its
  neighbours' readings, discarded because the link was re-established, are consequences).
* A stage whose replies keep arriving corrupted fails with that cause in its reason, not with
  the "does not answer" of a later reconnect attempt.
* A device that stops answering for longer than the retries last (an unplugged cable) keeps the
  job suspended until it answers again; the job then resumes from its checkpoint and completes.
"""

from __future__ import annotations

import asyncio
import threading

import pytest

from gonio.jobstates import JobState
from gonio.plans.models import ExposureSettings, FaultPolicy, UniformPlan
from gonio.sim.rig import SimRigOptions, start_sim_rig
from tests.system.test_scan_sim import _scan

pytestmark = [pytest.mark.system, pytest.mark.timeout(300)]

FAST = ExposureSettings(exposure_s=0.02, light_settle_s=0.0, dark="every_angle")


def _fault_devices(store) -> list[str]:  # type: ignore[no-untyped-def]
    """Devices named by every suspension and fault event of job 1."""
    out = []
    for e in store.events_after(0):
        suspended = e.type == "state" and e.data.get("state") == "suspended"
        if (suspended and "device" in e.data) or e.type == "fault":
            out.append(e.data["device"])
    return out


def test_silent_sensor_on_a_shared_link_is_the_one_blamed() -> None:
    policy = FaultPolicy(max_retries=2, retry_delay_s=0.05, resume_settle_s=0.0,
                         wait_for_device_s=0)
    with start_sim_rig(SimRigOptions(stage="zaber", time_scale=10.0, seed=8)) as sim:
        # Every lamp and sensor of the simulated rig sits behind one Modbus TCP server.
        ports = {(s.modbus.host, s.modbus.port) for s in sim.config.sensors}
        assert len(ports) == 1
        store, _, state = asyncio.run(_scan(sim, UniformPlan(rotations=3, exposure=FAST,
                                                             faults=policy), "silence:S2"))
    assert state is JobState.FAILED
    reason = store.get_job(1).reason or ""
    assert reason.startswith("device fault persisted after 2 retries: S2:"), reason
    assert "S1:" not in reason and "S3:" not in reason and "S4:" not in reason
    devices = _fault_devices(store)
    assert devices and set(devices) == {"S2"}, devices


def test_corrupted_stage_replies_keep_their_cause_in_the_final_reason() -> None:
    policy = FaultPolicy(max_retries=2, retry_delay_s=0.05, resume_settle_s=0.0,
                         wait_for_device_s=0)
    with start_sim_rig(SimRigOptions(stage="dynamixel", time_scale=10.0, seed=9)) as sim:
        def corrupt_once_running(store) -> None:  # type: ignore[no-untyped-def]
            def listener(ev) -> None:  # type: ignore[no-untyped-def]
                if ev.type == "state" and ev.data.get("state") == "running":
                    # Enough corrupted replies to outlast the driver's attempts, the engine's
                    # retries and every reconnect: only corrupted packets come back from now.
                    sim.stage_faults.set(corrupt_replies=10_000)
            store.add_listener(listener)

        store, _, state = asyncio.run(_scan(sim, UniformPlan(rotations=3, start_deg=30,
                                                             exposure=FAST, faults=policy),
                                            on_store=corrupt_once_running))
    assert state is JobState.FAILED
    reason = store.get_job(1).reason or ""
    assert reason.startswith("device fault persisted after 2 retries: stage:"), reason
    # The SDK's own words for a bad packet, from the first fault and the last one.
    assert "Incorrect status packet" in reason or "corrupted" in reason, reason
    assert "does not answer" not in reason, reason


def test_an_outage_longer_than_the_retries_suspends_until_the_device_answers() -> None:
    # Retries alone would give up after about 2 x 0.1 s plus two request timeouts; the sensor
    # is gone for 4 s (time enough to replug a cable, at this scale).
    policy = FaultPolicy(max_retries=2, retry_delay_s=0.1, resume_settle_s=0.0,
                         wait_for_device_s=120)
    outage_s = 4.0
    with start_sim_rig(SimRigOptions(stage="zaber", time_scale=10.0, seed=10)) as sim:
        armed = threading.Event()

        def unplug_after_first_angle(store) -> None:  # type: ignore[no-untyped-def]
            def listener(ev) -> None:  # type: ignore[no-untyped-def]
                if ev.type == "progress" and ev.data.get("done") == 1 and not armed.is_set():
                    armed.set()
                    sim.apply_fault(f"silence:S3:{outage_s}")
            store.add_listener(listener)

        store, _, state = asyncio.run(_scan(
            sim, UniformPlan(rotations=4, exposure=FAST, faults=policy),
            on_store=unplug_after_first_angle))
    assert armed.is_set()
    assert state is JobState.RUNNING, store.get_job(1).reason  # measured to the end
    assert store.get_job(1).done_angles == 4
    events = store.events_after(0)
    waits = [e for e in events if e.type == "fault" and "waiting_s" in e.data]
    assert waits and waits[0].data["device"] == "S3"
    assert "does not answer; waiting up to" in waits[0].data["note"]
    assert any(e.type == "recovered" and e.data["device"] == "S3" for e in events)
    # One waiting announcement, not one event per probe.
    assert len(waits) <= 2
    # Nothing lost, nothing doubled: every angle has all its readings once.
    keys = [(r.angle_index, r.light, r.sensor) for r in store.readings(1)]
    assert len(keys) == len(set(keys)) == 4 * 12


def test_a_lamp_out_of_band_at_switch_on_suspends_with_the_drivers_message() -> None:
    # The engine switches a lamp on without reading its monitor and checks the output while
    # the sensors integrate: the fault must still name the lamp, its output and the band.
    policy = FaultPolicy(max_retries=1, retry_delay_s=0.05, resume_settle_s=0.0,
                         wait_for_device_s=0)
    with start_sim_rig(SimRigOptions(stage="zaber", time_scale=10.0, seed=11)) as sim:
        lamp = next(lt for lt in sim.config.lights if lt.name == "L2")
        regs = lamp.registers
        assert regs.monitor is not None
        store, _, state = asyncio.run(_scan(
            sim, UniformPlan(rotations=2, exposure=FAST, faults=policy), "lamp-drift:L2:0.5"))
    assert state is JobState.FAILED
    suspended = [e.data for e in store.events_after(0)
                 if e.type == "state" and e.data.get("state") == "suspended"]
    assert suspended and (suspended[0]["device"], suspended[0]["code"]) == ("L2", "out_of_band")
    # Half the drive level, to the monitor register's resolution (its scale).
    output = round(0.5 * lamp.level / regs.monitor.scale) * regs.monitor.scale
    assert suspended[0]["reason"] == (
        f"L2: output {output:.3f} is outside {lamp.level:.3f} +- {regs.band:.3f}; check the "
        "lamp or lengthen warmup_s")
    # Nothing of an angle with the bad lamp was kept.
    assert all(r.light != "L2" for r in store.readings(1))


def test_the_wait_has_a_ceiling() -> None:
    policy = FaultPolicy(max_retries=1, retry_delay_s=0.1, resume_settle_s=0.0,
                         wait_for_device_s=1.5)
    with start_sim_rig(SimRigOptions(stage="zaber", time_scale=10.0, seed=11)) as sim:
        store, _, state = asyncio.run(_scan(sim, UniformPlan(rotations=2, exposure=FAST,
                                                             faults=policy), "silence:S4"))
    assert state is JobState.FAILED
    reason = store.get_job(1).reason or ""
    assert "S4:" in reason and "wait_for_device_s 1.5" in reason, reason


async def _scan_homed(sim, plan: UniformPlan, cycle_after: int):  # type: ignore[no-untyped-def]
    """Home the stage where it stands (0 deg), scan, and power-cycle the servo once
    ``cycle_after`` angles are committed; the store, the driver's position after the scan
    and the state."""
    from gonio.drivers.factory import build_rig
    from gonio.engine import ScanEngine
    from gonio.rigdescription import RigDescription
    from gonio.store import JobStore

    rig = build_rig(sim.config)
    desc = RigDescription.from_rig(rig)
    store = JobStore(":memory:")
    armed = threading.Event()

    def listener(ev) -> None:  # type: ignore[no-untyped-def]
        if ev.type == "progress" and ev.data.get("done") == cycle_after and not armed.is_set():
            armed.set()
            sim.apply_fault("stage-power-cycle:1")
    store.add_listener(listener)
    job = store.create_job(kind=plan.kind, specimen="sim", plan=plan.model_dump(mode="json"),
                           rig=desc.model_dump(mode="json"))
    async with rig:
        await rig.stage.home()
        state = await ScanEngine(rig, store, job.id, plan, desc).run()
        position = await rig.stage.position()
    assert armed.is_set()
    return store, position, state


@pytest.mark.parametrize("gear", [1.0, 3.0])
def test_a_servo_powered_off_mid_scan_loses_its_zero_only_when_geared(gear: float) -> None:
    """A Dynamixel homed before the job is powered off for a second after two angles
    (100 and 145 deg) and comes back. Direct drive (gear 1): its one-turn encoder and the
    zero in EEPROM hold, the job waits for it and completes at the right angles. Geared
    3:1: the encoder keeps 145 * 3 = 435 deg of motor only modulo one turn, so the stage
    reads 145 - 360 / 3 = 25 deg (or 190 - 120 = 70); the job went on reading at angles
    120 deg off, labelled as planned. Now it fails saying why, the two angles read kept."""
    policy = FaultPolicy(max_retries=2, retry_delay_s=0.1, resume_settle_s=0.0,
                         wait_for_device_s=120)
    plan = UniformPlan(rotations=4, start_deg=100, exposure=FAST, faults=policy)
    with start_sim_rig(SimRigOptions(stage="dynamixel", stage_gear=gear, time_scale=10.0,
                                     seed=12)) as sim:
        store, position, state = asyncio.run(_scan_homed(sim, plan, cycle_after=2))
        truth = sim.motion.position_deg()
    readings = store.readings(1)
    assert all(abs(r.actual_deg - r.commanded_deg) < 0.2 for r in readings)
    reason = store.get_job(1).reason or ""
    if gear == 1.0:
        assert state is JobState.RUNNING, reason  # measured to the end
        assert {r.angle_index for r in readings} == {0, 1, 2, 3}
        assert position == pytest.approx(truth, abs=0.2)
        return
    assert state is JobState.FAILED
    assert reason.startswith("the stage lost its zero during the job"), reason
    assert "The readings of the 2 angles measured before stay in the job store" in reason, \
        reason
    assert {r.angle_index for r in readings} == {0, 1}
    # The premise, from the gearing alone: the servo (at 145 deg, or at 190 when the next
    # move was under way as the power went) now reads one motor turn short.
    assert min(abs(truth - 145.0), abs(truth - 190.0)) < 0.2, truth
    assert position == pytest.approx(truth - 360.0 / gear, abs=0.2)
    ref = store.last_event(1, "stage_reference")
    assert ref is not None and ref.data["homed"] is True
