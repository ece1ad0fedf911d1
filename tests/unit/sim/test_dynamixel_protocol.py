"""Dynamixel Protocol 2.0: codec byte tables and the simulated servo's control-table rules.

The example frames are the ones printed in the ROBOTIS e-manual (Protocol 2.0 page): PING,
READ of Present Position, WRITE of Goal Position 512 and REBOOT to ID 1, with their status
packets.
"""

from __future__ import annotations

import dynamixel_sdk as sdk
import pytest
from hypothesis import given
from hypothesis import strategies as st

from gonio.sim import dynamixel_protocol as dxl
from gonio.sim.dynamixel_device import DynamixelAdapter, XSeriesServo
from gonio.sim.faults import FaultPlan
from gonio.sim.motion import StageMotion

H = bytes.fromhex

EMANUAL_FRAMES = [
    # (description, encoder, args, frame)
    ("ping ID 1", dxl.encode_instruction, (1, dxl.PING, b""), H("ff ff fd 00 01 03 00 01 19 4e")),
    ("read Present Position", dxl.encode_instruction, (1, dxl.READ, H("84000400")),
     H("ff ff fd 00 01 07 00 02 84 00 04 00 1d 15")),
    ("write Goal Position 512", dxl.encode_instruction, (1, dxl.WRITE, H("740000020000")),
     H("ff ff fd 00 01 09 00 03 74 00 00 02 00 00 ca 89")),
    ("reboot ID 1", dxl.encode_instruction, (1, dxl.REBOOT, b""),
     H("ff ff fd 00 01 03 00 08 2f 4e")),
    ("ping status model 1030 fw 38", dxl.encode_status, (1, 0, H("060426")),
     H("ff ff fd 00 01 07 00 55 00 06 04 26 65 5d")),
    ("read status 166", dxl.encode_status, (1, 0, H("a6000000")),
     H("fffffd000108005500a60000008cc0")),
    ("write status", dxl.encode_status, (1, 0, b""), H("ff ff fd 00 01 04 00 55 00 a1 0c")),
]


def test_crc_check_value() -> None:
    # CRC-16/UMTS (poly 0x8005, init 0, unreflected): catalogue check value.
    assert dxl.crc16(b"123456789") == 0xFEE8


@given(st.binary(max_size=300))
def test_crc_matches_the_sdk(data: bytes) -> None:
    assert dxl.crc16(data) == sdk.Protocol2PacketHandler().updateCRC(0, list(data), len(data))


@pytest.mark.parametrize(("what", "encode", "args", "frame"), EMANUAL_FRAMES,
                         ids=[f[0] for f in EMANUAL_FRAMES])
def test_emanual_example_frames(what: str, encode: object, args: tuple, frame: bytes) -> None:
    assert encode(*args) == frame  # type: ignore[operator]
    packet = dxl.decode(frame)
    assert packet.crc_ok and packet.dxl_id == 1


def test_decoded_status_separates_error_and_params() -> None:
    p = dxl.decode(H("fffffd000108005500a60000008cc0"))
    assert (p.instruction, p.error, p.params) == (dxl.STATUS, 0, H("a6000000"))


@pytest.mark.parametrize(
    ("body", "stuffed"),
    [
        (H("03ffffff"), H("03ffffff")),
        (H("03fffffd00"), H("03fffffdfd00")),
        (H("03fffffdfffffd"), H("03fffffdfdfffffdfd")),
        (H("03fffffdfd"), H("03fffffdfdfd")),
        (H("03fffdfffd"), H("03fffdfffd")),
    ],
)
def test_byte_stuffing_table(body: bytes, stuffed: bytes) -> None:
    assert dxl.stuff(body) == stuffed
    assert dxl.unstuff(stuffed) == body


@given(st.lists(st.sampled_from([0xFF, 0xFD, 0x00, 0x55]), max_size=40).map(bytes))
def test_stuffing_round_trips_and_matches_the_sdk(params: bytes) -> None:
    frame = dxl.encode_instruction(1, dxl.WRITE, params)
    assert dxl.decode(frame).params == params
    body = frame[7:-2]
    # Every header-like FF FF FD inside the stuffed body is followed by its stuffing FD.
    # (Deleting each FF FF FD FD instead would splice new FF FF FD out of the bytes around it.)
    i = body.find(b"\xff\xff\xfd")
    while i != -1:
        assert body[i + 3 : i + 4] == b"\xfd", body.hex()
        i = body.find(b"\xff\xff\xfd", i + 4)
    # The SDK stuffs a raw packet in place; its LEN must agree with ours.
    raw = [0xFF, 0xFF, 0xFD, 0, 1, 0, 0, dxl.WRITE, *params, 0, 0]
    raw[5], raw[6] = (len(params) + 3) & 0xFF, (len(params) + 3) >> 8
    ours = int.from_bytes(frame[5:7], "little")
    theirs = sdk.Protocol2PacketHandler().addStuffing(raw)
    assert ours == theirs[5] | theirs[6] << 8


def test_parser_skips_garbage_handles_split_input_and_flags_bad_crc() -> None:
    good = dxl.encode_instruction(1, dxl.PING)
    bad = bytearray(dxl.encode_instruction(1, dxl.READ, H("84000400")))
    bad[-1] ^= 0xFF
    parser = dxl.PacketParser()
    got: list[dxl.Packet] = []
    for byte in b"\x00\xff\x13" + good + bytes(bad):
        got += parser.feed(bytes([byte]))
    assert [(p.instruction, p.crc_ok) for p in got] == [(dxl.PING, True), (dxl.READ, False)]


def test_decode_rejects_a_partial_frame() -> None:
    with pytest.raises(ValueError, match=r"expected one Dynamixel 2\.0 frame"):
        dxl.decode(H("fffffd000103"))


# --------------------------------------------------------------------------- simulated servo
Servo = tuple[DynamixelAdapter, FaultPlan]


@pytest.fixture
def servo() -> Servo:
    faults = FaultPlan()
    s = XSeriesServo(StageMotion(time_scale=1000.0), dxl_id=1, faults=faults)
    return DynamixelAdapter(s, faults), faults


def ask(
    adapter: DynamixelAdapter, inst: int, params: bytes = b"", dxl_id: int = 1
) -> dxl.Packet | None:
    out = adapter.handle(dxl.encode_instruction(dxl_id, inst, params))
    return dxl.decode(out) if out else None


def write(adapter: DynamixelAdapter, addr: int, data: bytes) -> int:
    p = ask(adapter, dxl.WRITE, addr.to_bytes(2, "little") + data)
    assert p is not None and p.error is not None
    return p.error


def read(adapter: DynamixelAdapter, addr: int, n: int) -> bytes:
    p = ask(adapter, dxl.READ, addr.to_bytes(2, "little") + n.to_bytes(2, "little"))
    assert p is not None and p.error == 0
    return p.params


def test_ping_reports_model_and_firmware(servo: Servo) -> None:
    p = ask(servo[0], dxl.PING)
    assert p is not None and p.params[:2] == (1020).to_bytes(2, "little") and len(p.params) == 3


def test_eeprom_is_writable_only_with_torque_off(servo: Servo) -> None:
    a, _ = servo
    assert write(a, 11, b"\x04") == 0
    assert write(a, 64, b"\x01") == 0
    assert write(a, 11, b"\x03") == dxl.ERR_ACCESS
    assert read(a, 11, 1) == b"\x04"  # unchanged


@pytest.mark.parametrize(
    ("addr", "data", "error"),
    [
        (11, b"\x02", dxl.ERR_DATA_RANGE),  # operating mode 2 does not exist
        (112, (40000).to_bytes(4, "little"), dxl.ERR_DATA_RANGE),
        (116, b"\x00\x02", dxl.ERR_DATA_LENGTH),  # half of Goal Position
        (132, (5).to_bytes(4, "little"), dxl.ERR_ACCESS),  # Present Position is read-only
        (200, b"\x00", dxl.ERR_ACCESS),
    ],
)
def test_write_errors(servo: Servo, addr: int, data: bytes, error: int) -> None:
    assert write(servo[0], addr, data) == error


def test_goal_range_depends_on_operating_mode(servo: Servo) -> None:
    a, _ = servo
    far = (10_000).to_bytes(4, "little", signed=True)
    assert write(a, 116, far) == dxl.ERR_DATA_RANGE  # position mode: 0..4095
    write(a, 11, b"\x04")
    assert write(a, 116, far) == 0


def test_overload_sets_alert_until_reboot(servo: Servo) -> None:
    a, faults = servo
    write(a, 11, b"\x04")
    write(a, 64, b"\x01")
    faults.set(overload_next_move=True)
    write(a, 116, (4096).to_bytes(4, "little"))
    a.servo.motion.overload_now()
    p = ask(a, dxl.PING)
    assert p is not None and p.error == dxl.ALERT_BIT
    status = ask(a, dxl.READ, H("46000100"))
    assert status is not None and status.params == b"\x20" and status.error == dxl.ALERT_BIT
    assert read_torque(a) == 0
    assert write(a, 64, b"\x01") == dxl.ALERT_BIT | dxl.ERR_RESULT_FAIL
    p = ask(a, dxl.REBOOT)
    assert p is not None and p.error == dxl.ALERT_BIT  # answered before restarting
    p = ask(a, dxl.PING)
    assert p is not None and p.error == 0


def read_torque(a: DynamixelAdapter) -> int:
    p = ask(a, dxl.READ, H("40000100"))
    assert p is not None
    return p.params[0]


def test_homing_offset_shifts_present_position(servo: Servo) -> None:
    a, _ = servo
    before = int.from_bytes(read(a, 132, 4), "little", signed=True)
    write(a, 20, (-1000).to_bytes(4, "little", signed=True))
    after = int.from_bytes(read(a, 132, 4), "little", signed=True)
    assert after == before - 1000


def test_broadcast_and_sync_instructions(servo: Servo) -> None:
    a, _ = servo
    assert ask(a, dxl.WRITE, H("4100") + b"\x01", dxl_id=dxl.BROADCAST_ID) is None
    assert read(a, 65, 1) == b"\x01"
    # SYNC_WRITE LED=0 to IDs 3 and 1: no reply, applied to ours.
    led_off = H("41000100") + b"\x03\x01" + b"\x01\x00"
    assert ask(a, dxl.SYNC_WRITE, led_off, dxl.BROADCAST_ID) is None
    assert read(a, 65, 1) == b"\x00"
    p = ask(a, dxl.SYNC_READ, H("84000400") + b"\x01", dxl.BROADCAST_ID)
    assert p is not None and len(p.params) == 4
    assert ask(a, dxl.READ, H("84000400"), dxl_id=7) is None  # another servo's ID


def test_unknown_instruction_and_bad_crc_get_error_status(servo: Servo) -> None:
    a, _ = servo
    p = ask(a, 0x42)
    assert p is not None and p.error == dxl.ERR_INSTRUCTION
    frame = bytearray(dxl.encode_instruction(1, dxl.PING))
    frame[-2] ^= 1
    reply = dxl.decode(a.handle(bytes(frame)))
    assert reply.error == dxl.ERR_CRC


def test_wire_faults_corrupt_then_drop(servo: Servo) -> None:
    a, faults = servo
    faults.set(corrupt_replies=1, drop_replies=1)
    out = a.handle(dxl.encode_instruction(1, dxl.PING))
    assert out == b""  # the drop is consumed first
    out = a.handle(dxl.encode_instruction(1, dxl.PING))
    assert not dxl.decode(out).crc_ok
    assert dxl.decode(a.handle(dxl.encode_instruction(1, dxl.PING))).crc_ok
    faults.set(silent=True)
    assert a.handle(dxl.encode_instruction(1, dxl.PING)) == b""
    with pytest.raises(ValueError, match="unknown stage fault"):
        faults.set(explode=True)


def test_stuffing_of_a_run_that_once_fooled_the_check() -> None:
    # Found by hypothesis: FF FF FF FF FD FD must become FF FF FF FF FD FD FD.
    body = bytes([dxl.WRITE]) + H("fffffffffdfd")
    assert dxl.stuff(body) == bytes([dxl.WRITE]) + H("fffffffffdfdfd")
    assert dxl.unstuff(dxl.stuff(body)) == body
