"""DynamixelStage (real dynamixel-sdk) against the simulated servo on a pseudo-terminal."""

from __future__ import annotations

import asyncio
import os
import statistics
import threading
import time
from collections.abc import Awaitable, Callable, Iterator
from contextlib import contextmanager
from typing import Any

import pytest

from gonio.drivers.dynamixel import DynamixelStage, _PortHandler
from gonio.hal import DeviceUnavailable, StageFault, TravelLimits
from gonio.motion import move_time
from gonio.sim.dynamixel_device import DynamixelSimHandle, start_dynamixel_sim
from gonio.sim.motion import StageMotion
from gonio.sim.rig import SIM_REPLY_TIMEOUT_S

pytestmark = [pytest.mark.system, pytest.mark.timeout(60)]

GEAR = 2.0
CPD = 4096 / 360 * GEAR
TIME_SCALE = 40.0


@contextmanager
def rig(time_scale: float = TIME_SCALE,
        **driver_kw: Any) -> Iterator[tuple[DynamixelSimHandle, DynamixelStage]]:
    motion = StageMotion(speed_dps=30.0, accel_dps2=60.0, settle_s=0.0, time_scale=time_scale)
    sim = start_dynamixel_sim(motion, counts_per_degree=CPD)
    kw: dict[str, Any] = {
        "counts_per_degree": CPD, "limits": TravelLimits(-720.0, 720.0),
        "speed_dps": 30.0, "accel_dps2": 60.0, "reply_timeout_s": SIM_REPLY_TIMEOUT_S,
        **driver_kw,
    }
    stage = DynamixelStage("rot", sim.port, **kw)
    try:
        yield sim, stage
    finally:
        asyncio.run(stage.close())
        sim.close()


def run(fn: Callable[[], Awaitable[Any]]) -> Any:
    return asyncio.run(fn())  # type: ignore[arg-type]


class Track:
    """Samples the simulated stage angle in a thread to see the path a move took."""

    def __init__(self, motion: StageMotion) -> None:
        self.motion, self.samples = motion, [motion.position_deg()]
        self._stop = threading.Event()
        self._t = threading.Thread(target=self._run, daemon=True)
        self._t.start()

    def _run(self) -> None:
        while not self._stop.wait(0.001):
            self.samples.append(self.motion.position_deg())

    def stop(self) -> list[float]:
        self._stop.set()
        self._t.join()
        return self.samples


def test_connect_configures_extended_mode_and_profile() -> None:
    with rig() as (sim, stage):
        run(stage.connect)
        table = sim.servo
        assert table.read(11, 1) == b"\x04"
        assert table.read(64, 1) == b"\x01"
        velocity = int.from_bytes(table.read(112, 4), "little")
        # 30 deg/s at the stage = 60 deg/s at the motor = 10 rpm = 44 units of 0.229 rpm.
        assert velocity == round(30 * GEAR / (0.229 * 6))
        assert stage.model_number == 1020


def test_profile_is_the_speed_and_acceleration_the_servo_runs() -> None:
    with rig() as (sim, stage):
        run(stage.connect)
        speed, accel = stage.profile_dps
        # ROBOTIS e-manual units: Profile Velocity 0.229 rpm = 1.374 motor deg/s, Profile
        # Acceleration 214.577 rev/min^2 = 21.4577 motor deg/s^2; the stage turns 1/GEAR as far.
        # 30 deg/s at the stage: 60 motor deg/s = 43.7 -> 44 units; 60 deg/s^2: 120 motor
        # deg/s^2 = 5.59 -> 6 units.
        assert speed == pytest.approx(44 * 1.374 / GEAR)
        assert accel == pytest.approx(6 * 21.4577 / GEAR)
        # ... which is what the simulated servo decoded from the registers and moves with.
        run(lambda: stage.move_to(10.0))
        assert (speed, accel) == pytest.approx((sim.motion.speed_dps, sim.motion.accel_dps2))
        assert (stage.speed_dps, stage.accel_dps2) == (30.0, 60.0)  # the config, kept


def test_moves_past_one_turn_and_approaches_from_the_positive_side() -> None:
    with rig(backlash_deg=2.0) as (sim, stage):
        async def go() -> tuple[float, float, list[float]]:
            await stage.connect()
            far = await stage.move_to(400.0)
            track = Track(sim.motion)
            back = await stage.move_to(390.0)
            return far, back, track.stop()

        far, back, path = run(go)
        assert far == pytest.approx(400.0, abs=1.5 / CPD)
        assert back == pytest.approx(390.0, abs=1.5 / CPD)
        assert sim.motion.position_deg() == pytest.approx(390.0, abs=1.5 / CPD)
        assert min(path) == pytest.approx(388.0, abs=0.05)  # overshoot, then up to the target


def test_travel_limits_are_refused_before_moving() -> None:
    with rig(limits=TravelLimits(0.0, 90.0)) as (sim, stage):
        run(stage.connect)
        with pytest.raises(ValueError, match=r"outside the travel limits \[0, 90\]"):
            run(lambda: stage.move_to(120.0))
        assert not sim.motion.is_moving() and sim.motion.position_deg() == 0.0


def test_corrupted_replies_are_retried() -> None:
    with rig() as (sim, stage):
        run(stage.connect)
        sim.faults.set(corrupt_replies=2)
        assert run(lambda: stage.move_to(5.0)) == pytest.approx(5.0, abs=1 / CPD)
        assert sim.faults.corrupt_replies == 0


def test_corrupted_replies_past_the_retries_are_reported_as_corrupt_not_timeout() -> None:
    # Every attempt answered, with a broken CRC: the fault says so, with its own code, so the
    # lab checks the wiring rather than the servo's power (issue 24, item 8).
    with rig(retries=3) as (sim, stage):
        run(stage.connect)
        sim.faults.set(corrupt_replies=3)
        with pytest.raises(DeviceUnavailable, match="corrupted status packets") as err:
            run(stage.position)
        assert err.value.code == "corrupt_reply"
        assert sim.faults.corrupt_replies == 0
        assert run(stage.position) == pytest.approx(0.0)  # the next request is answered


def test_dropped_replies_retry_then_device_unavailable() -> None:
    with rig(retries=3) as (sim, stage):
        run(stage.connect)
        sim.faults.set(drop_replies=2)
        assert run(stage.position) == pytest.approx(0.0)
        sim.faults.set(drop_replies=3)
        with pytest.raises(DeviceUnavailable, match="after 3 attempts") as err:
            run(stage.position)
        assert err.value.code == "timeout"


def test_stall_raises_stage_fault() -> None:
    with rig() as (sim, stage):
        run(stage.connect)
        sim.faults.set(stall_next_move=True, stall_fraction=0.5)
        with pytest.raises(StageFault, match="short of the target") as err:
            run(lambda: stage.move_to(20.0))
        assert err.value.code == "stall"
        assert sim.motion.position_deg() == pytest.approx(10.0, abs=0.01)


def test_overload_is_a_typed_fault_and_reboot_keeps_the_multiturn_reference() -> None:
    with rig() as (sim, stage):
        async def go() -> None:
            await stage.connect()
            await stage.move_to(400.0)  # beyond one motor turn
            sim.faults.set(overload_next_move=True)
            with pytest.raises(StageFault) as err:
                await stage.move_to(420.0)
            assert err.value.code == "overload" and err.value.recoverable
            status = await stage.status()
            assert status.faults == ("overload",)
            tripped_at = await stage.position()
            await stage.clear_faults()
            assert (await stage.status()).faults == ()
            assert await stage.position() == pytest.approx(tripped_at, abs=1 / CPD)
            assert await stage.move_to(420.0) == pytest.approx(420.0, abs=1.5 / CPD)

        run(go)
        assert sim.motion.position_deg() == pytest.approx(420.0, abs=1.5 / CPD)


def test_home_makes_the_present_position_zero() -> None:
    with rig() as (sim, stage):
        async def go() -> float:
            await stage.connect()
            await stage.move_to(33.0)
            await stage.home()
            assert (await stage.status()).homed
            return await stage.position()

        assert run(go) == pytest.approx(0.0, abs=1 / CPD)
        assert sim.motion.position_deg() == pytest.approx(33.0, abs=1 / CPD)


def test_move_timeout_stops_the_stage() -> None:
    with rig() as (sim, stage):
        run(stage.connect)
        with pytest.raises(DeviceUnavailable, match=r"did not finish within 0\.05 s") as err:
            run(lambda: stage.move_to(600.0, timeout_s=0.05))
        assert err.value.code == "timeout"
        run(lambda: asyncio.sleep(0.3))
        assert not sim.motion.is_moving()
        assert sim.motion.position_deg() < 600.0


def test_reconnects_after_the_port_is_lost() -> None:
    with rig() as (_sim, stage):
        run(stage.connect)
        stage._ph.ser.close()  # the adapter vanished under the SDK
        assert run(lambda: stage.move_to(3.0)) == pytest.approx(3.0, abs=1 / CPD)


def test_silent_device_gives_a_clear_device_unavailable() -> None:
    with rig(retries=2) as (sim, stage):
        sim.faults.set(silent=True)
        with pytest.raises(DeviceUnavailable, match=r"ID 1 does not answer .* check power"):
            run(stage.connect)


def test_missing_port_and_bad_speed_are_user_errors(tmp_path: Any) -> None:
    port = str(tmp_path / "ttyUSB9")
    stage = DynamixelStage("rot", port, counts_per_degree=CPD,
                           limits=TravelLimits(0, 90), speed_dps=10, accel_dps2=10)
    with pytest.raises(DeviceUnavailable, match=r"serial port .* does not exist") as err:
        run(stage.connect)
    # pyserial's "[Errno 2] could not open port P: [Errno 2] No such file ...: 'P'" is said in
    # words, the port named once.
    assert "Errno" not in str(err.value) and str(err.value).count(port) == 1, err.value
    assert "check the USB adapter and the port name" in str(err.value)
    with pytest.raises(ValueError, match="above the servo maximum 32767; lower speed_dps"):
        DynamixelStage("rot", "x", counts_per_degree=CPD, limits=TravelLimits(0, 90),
                       speed_dps=50_000, accel_dps2=10)


def test_a_port_that_disappears_mid_run_is_said_once_in_words() -> None:
    """The adapter unplugged after connecting: the fault says the port is gone and what to
    check, once; it said "no valid reply ... (rot: cannot open serial port 'P': [Errno 2]
    could not open port P: [Errno 2] No such file or directory: 'P'; check ...); check power,
    cable, ID and baud rate"."""
    with rig(retries=2) as (sim, stage):
        run(stage.connect)
        port = sim.port
        sim.close()
        with pytest.raises(DeviceUnavailable) as err:
            run(stage.status)
    said = str(err.value)
    assert said.startswith(f"rot: serial port {port!r} does not exist"), said
    assert "Errno" not in said and said.count(port) == 1, said
    assert err.value.code == "port"


def test_arrival_is_seen_soon_after_the_move_ends_despite_a_slow_poll() -> None:
    """In real time: the coarse poll (100 ms here) would find the end 50 ms late on average;
    predicting the end from the profile and polling finely from there finds it within a few
    milliseconds (the rest is the goal write and position reads)."""
    speed, accel, step = 180.0, 1800.0, 9.0
    with rig(time_scale=1.0, speed_dps=speed, accel_dps2=accel, poll_interval_s=0.1) as (
            sim, stage):
        async def go() -> list[float]:
            await stage.connect()
            late = []
            for k in range(1, 6):
                t0 = time.monotonic()
                await stage.move_to(k * step)
                late.append(time.monotonic() - t0 - move_time(step, speed, accel))
            return late

        late = run(go)
        assert sim.motion.position_deg() == pytest.approx(5 * step, abs=1.5 / CPD)
    # How soon after the end the arrival is seen is a speed figure, measured by
    # bench/bench_engine.py ("stage move" overhead), not asserted here: on a saturated machine
    # it depends on the scheduler.
    print(f"arrival seen {1000 * statistics.median(late):.1f} ms after the move's end (median)")


def test_poll_interval_must_be_positive() -> None:
    with pytest.raises(ValueError, match="poll_interval_s must be > 0"):
        DynamixelStage("rot", "/dev/null", counts_per_degree=CPD,
                       limits=TravelLimits(0.0, 360.0), speed_dps=30.0, accel_dps2=60.0,
                       poll_interval_s=-0.01)


def test_a_stale_start_position_only_times_the_polls_never_the_arrival() -> None:
    """Without an approach side the driver starts from where its last move came to rest
    instead of reading it; if something else moved the servo meanwhile, the move must still
    end on the target."""
    with rig(approach="none") as (sim, stage):
        async def go() -> tuple[float, float]:
            await stage.connect()
            first = await stage.move_to(10.0)
            sim.motion.move_to(50.0)  # pushed elsewhere behind the driver's back
            while sim.motion.is_moving():
                await asyncio.sleep(0.005)
            return first, await stage.move_to(20.0)

        first, second = run(go)
        assert first == pytest.approx(10.0, abs=1.5 / CPD)
        assert second == pytest.approx(20.0, abs=1.5 / CPD)
        assert sim.motion.position_deg() == pytest.approx(20.0, abs=1.5 / CPD)


@contextmanager
def _port_pair() -> Iterator[tuple[Any, int, list[int]]]:
    """The driver's port handler on one end of a pseudo-terminal, the other end's file
    descriptor, and a list that counts the handler's reads of the port."""
    master, slave = os.openpty()
    ph = _PortHandler(os.ttyname(slave))
    try:
        assert ph.setBaudRate(57600)
        reads: list[int] = []
        read = ph.ser.read

        def counted(n: int) -> bytes:
            reads.append(n)
            data: bytes = read(n)
            return data

        ph.ser.read = counted
        yield ph, master, reads
    finally:
        ph.closePort()
        os.close(master)
        os.close(slave)


def test_a_reply_is_waited_for_without_spinning_on_the_port() -> None:
    # The SDK reads the port in a loop until the status packet is complete: a non-blocking
    # read there spins a core for the whole reply latency. The handler waits for the bytes.
    with _port_pair() as (ph, master, reads):
        ph.setPacketTimeoutMillis(5000.0)
        reply = bytes([0xFF, 0xFF, 0xFD, 0x00, 0x01, 0x04, 0x00, 0x55, 0x00, 0xA1, 0x0C])
        late = threading.Timer(0.05, os.write, (master, reply))
        late.start()
        try:
            got = ph.readPort(len(reply))
        finally:
            late.cancel()
        assert got == reply
        assert len(reads) == 1  # one read, when the bytes were there
        assert not ph.isPacketTimeout()


def test_no_reply_returns_nothing_once_the_packet_timeout_has_passed() -> None:
    with _port_pair() as (ph, _master, reads):
        ph.setPacketTimeoutMillis(100.0)
        assert ph.readPort(11) == b""
        assert len(reads) == 1
        assert ph.isPacketTimeout()  # it gave up only when the SDK's timeout had passed


def _kept_servo(cpd: float, eeprom: Any) -> tuple[DynamixelSimHandle, DynamixelStage,
                                                   StageMotion]:
    """A simulated servo geared ``cpd`` keeping its EEPROM in ``eeprom``, the driver on it
    (not connected), and its motion."""
    motion = StageMotion(speed_dps=30.0, accel_dps2=60.0, settle_s=0.0, time_scale=TIME_SCALE)
    sim = start_dynamixel_sim(motion, counts_per_degree=cpd, eeprom_file=eeprom)
    stage = DynamixelStage("rot", sim.port, counts_per_degree=cpd,
                           limits=TravelLimits(-720.0, 720.0), speed_dps=30.0, accel_dps2=60.0,
                           reply_timeout_s=SIM_REPLY_TIMEOUT_S)
    return sim, stage, motion


def test_the_zero_outlives_a_restart_of_the_simulated_servo(tmp_path: Any) -> None:
    """The Homing Offset is EEPROM: a real servo keeps the zero ``home()`` set across a power
    cycle, and the simulator, given a file to keep its EEPROM in, keeps it across a restart
    (``gonio serve --sim`` restarted mid-scan forgot it, and the resumed scan read the stage
    turned by the old zero). Its LED is RAM (docs/stages.md): not homed after the restart.
    Expected angles from the spec's Present Position = encoder + Homing Offset."""
    eeprom = tmp_path / "eeprom.json"

    def servo() -> tuple[DynamixelSimHandle, DynamixelStage, StageMotion]:
        return _kept_servo(CPD, eeprom)

    sim, stage, motion = servo()
    try:
        async def home_at_33() -> None:
            await stage.connect()
            await stage.move_to(33.0)
            await stage.home()

        run(home_at_33)
        assert motion.position_deg() == pytest.approx(33.0, abs=1 / CPD)
    finally:
        asyncio.run(stage.close())
        sim.close()
    assert eeprom.exists()

    # Restarted: the simulated stage starts at its physical 0, which is -33 degrees from
    # the zero set above.
    sim, stage, motion = servo()
    try:
        async def read() -> tuple[float, bool]:
            await stage.connect()
            return await stage.position(), (await stage.status()).homed

        at, homed = run(read)
        assert motion.position_deg() == pytest.approx(0.0, abs=1 / CPD)
        assert at == pytest.approx(-33.0, abs=2 / CPD)
        assert not homed
    finally:
        asyncio.run(stage.close())
        sim.close()

    # An unreadable file is a servo that lost its EEPROM: factory values (no offset).
    eeprom.write_text("{ damaged")
    sim, stage, motion = servo()
    try:
        assert run(lambda: _connect_and_read(stage)) == pytest.approx(0.0, abs=2 / CPD)
    finally:
        asyncio.run(stage.close())
        sim.close()


def test_the_kept_zero_is_only_that_servos_and_a_failed_save_keeps_it_answering(
        tmp_path: Any) -> None:
    """The EEPROM file holds the servo's model and gearing: one kept for another gear ratio
    would move the zero by the wrong number of counts, so it is left (factory values). A save
    that fails (its folder removed: a full disk the same) left the simulator's serial thread
    dead, the stage silent for the rest of the session; the value stays in the servo's
    memory and it answers on."""
    eeprom = tmp_path / "eeprom.json"

    def homed_at(cpd: float, where: Any, angle: float) -> float:
        sim, stage, _motion = _kept_servo(cpd, where)
        try:
            async def go() -> float:
                await stage.connect()
                at = await stage.position()
                await stage.move_to(at + angle)
                await stage.home()
                # It answers after the EEPROM write, at its new zero.
                assert await stage.position() == pytest.approx(0.0, abs=2 / cpd)
                return at

            return float(run(go))
        finally:
            asyncio.run(stage.close())
            sim.close()

    homed_at(CPD, eeprom, 33.0)  # kept for gear 2
    # The same file given to a servo geared 1: not its EEPROM, so it starts at factory zero.
    assert homed_at(4096 / 360, eeprom, 0.0) == pytest.approx(0.0, abs=2 * 360 / 4096)
    # The gear-2 servo still finds its own zero (the gear-1 servo's home rewrote the file
    # for gear 1, so first keep gear 2's again).
    homed_at(CPD, eeprom, 33.0)
    assert homed_at(CPD, eeprom, 0.0) == pytest.approx(-33.0, abs=2 / CPD)
    # A file that cannot be written: home works and the servo answers after it.
    gone = tmp_path / "removed" / "eeprom.json"
    assert homed_at(CPD, gone, 10.0) == pytest.approx(0.0, abs=2 / CPD)
    assert not gone.exists()


async def _connect_and_read(stage: DynamixelStage) -> float:
    await stage.connect()
    return await stage.position()
