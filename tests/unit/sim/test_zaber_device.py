"""Zaber ASCII protocol: the simulator's replies and rejections, and the driver's reply parser."""

from __future__ import annotations

import pytest

from gonio.drivers.zaber import Reply
from gonio.sim.faults import FaultPlan
from gonio.sim.motion import StageMotion
from gonio.sim.zaber_device import SPEED_FACTOR, ZaberAsciiAdapter, ZaberRotaryAxis


class FakeClock:
    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


@pytest.fixture
def sim() -> tuple[ZaberAsciiAdapter, FakeClock, FaultPlan]:
    clock = FakeClock()
    motion = StageMotion(speed_dps=10.0, accel_dps2=100.0, settle_s=0.0, clock=clock,
                         initial_deg=3.0)
    faults = FaultPlan()
    axis = ZaberRotaryAxis(motion, microsteps_per_degree=100.0, faults=faults)
    return ZaberAsciiAdapter(axis, device=1, faults=faults), clock, faults


def home(a: ZaberAsciiAdapter, clock: FakeClock) -> None:
    assert a.reply_to("/1 1 home") == "@01 1 OK BUSY WR 0"
    clock.t += 10.0


@pytest.mark.parametrize(
    ("command", "reply"),
    [
        ("/", "@01 0 OK IDLE WR 0"),
        ("/1", "@01 0 OK IDLE WR 0"),
        ("/1 1 get pos", "@01 1 OK IDLE WR 0"),  # counts from power-up until homed
        ("/1 1 7 get pos", "@01 1 7 OK IDLE WR 0"),  # message ID echoed
        ("/0 1 get maxspeed", f"@01 1 OK IDLE WR {round(10 * 100 * SPEED_FACTOR)}"),
        ("/1 1 move abs 100", "@01 1 RJ IDLE WR BADCOMMAND"),  # no reference yet
        ("/1 2 get pos", "@01 2 RJ IDLE WR BADAXIS"),
        ("/1 1 fly", "@01 1 RJ IDLE WR BADCOMMAND"),
        ("/1 1 set maxspeed fast", "@01 1 RJ IDLE WR BADDATA"),
        ("/1 1 set maxspeed 0", "@01 1 RJ IDLE WR BADDATA"),
        ("/1 1 warnings", "@01 1 OK IDLE WR 01 WR"),
        ("/2 1 get pos", None),  # another device on the chain
        ("garbage", None),
    ],
)
def test_replies_before_homing(
    sim: tuple[ZaberAsciiAdapter, FakeClock, FaultPlan], command: str, reply: str | None
) -> None:
    assert sim[0].reply_to(command) == reply


def test_home_then_move_reports_busy_then_position(
    sim: tuple[ZaberAsciiAdapter, FakeClock, FaultPlan],
) -> None:
    a, clock, _ = sim
    home(a, clock)
    assert a.reply_to("/1 1 get pos") == "@01 1 OK IDLE -- 0"
    assert a.reply_to("/1 1 move abs 500") == "@01 1 OK BUSY -- 0"
    clock.t += 0.2
    assert a.reply_to("/1 1") == "@01 1 OK BUSY -- 0"
    clock.t += 10.0
    assert a.reply_to("/1 1 get pos") == "@01 1 OK IDLE -- 500"
    assert a.reply_to("/1 1 move rel -200") == "@01 1 OK BUSY -- 0"
    clock.t += 10.0
    assert a.reply_to("/1 1 get pos") == "@01 1 OK IDLE -- 300"


def test_stop_during_move_sets_interrupted_notice(
    sim: tuple[ZaberAsciiAdapter, FakeClock, FaultPlan],
) -> None:
    a, clock, _ = sim
    home(a, clock)
    a.reply_to("/1 1 move abs 5000")
    clock.t += 1.0
    assert a.reply_to("/1 1 stop") == "@01 1 OK BUSY NI 0"
    clock.t += 1.0
    assert a.reply_to("/1 1 warnings") == "@01 1 OK IDLE NI 01 NI"


def test_stall_latches_fs_until_warnings_clear(
    sim: tuple[ZaberAsciiAdapter, FakeClock, FaultPlan],
) -> None:
    a, clock, faults = sim
    home(a, clock)
    faults.set(stall_next_move=True, stall_fraction=0.5)
    a.reply_to("/1 1 move abs 1000")
    clock.t += 10.0
    assert a.reply_to("/1 1 get pos") == "@01 1 OK IDLE FS 500"
    assert a.reply_to("/1 1") == "@01 1 OK IDLE FS 0"  # persists
    assert a.reply_to("/1 1 warnings clear") == "@01 1 OK IDLE -- 01 FS"
    assert a.reply_to("/1 1 warnings") == "@01 1 OK IDLE -- 00"


def test_line_endings_faults_and_framing(
    sim: tuple[ZaberAsciiAdapter, FakeClock, FaultPlan],
) -> None:
    a, _, faults = sim
    assert a.handle(b"/1 1 get po") == b""  # incomplete line: no reply yet
    assert a.handle(b"s\r\n/1 get accel\n") == (
        b"@01 1 OK IDLE WR 0\r\n@01 0 OK IDLE WR " + str(a.axis.accel).encode() + b"\r\n"
    )
    faults.set(drop_replies=1, corrupt_replies=1)
    assert a.handle(b"/1\n") == b""
    garbled = a.handle(b"/1\n")
    assert garbled.endswith(b"\r\n")
    assert Reply.parse(garbled.decode("ascii", "replace").strip()) is None


@pytest.mark.parametrize(
    ("line", "expected"),
    [
        ("@01 0 OK BUSY -- 0", Reply(1, 0, None, True, True, None, "0")),
        ("@01 1 12 OK IDLE WR 0", Reply(1, 1, 12, True, False, "WR", "0")),
        ("@02 1 RJ IDLE -- BADDATA", Reply(2, 1, None, False, False, None, "BADDATA")),
        ("@01 1 3 OK IDLE FS 02 FS WR", Reply(1, 1, 3, True, False, "FS", "02 FS WR")),
        ("@01 1 OK IDLE --", Reply(1, 1, None, True, False, None, "")),
        ("@01 1 OK SLEEPY -- 0", None),
        ("#01 1 info", None),
        ("\x15\x02", None),
    ],
)
def test_driver_reply_parser(line: str, expected: Reply | None) -> None:
    assert Reply.parse(line) == expected
