"""Dynamixel Protocol 2.0 packet codec: CRC, byte stuffing, framing and an incremental parser.

Written from the ROBOTIS e-manual description of the protocol, independently of the
``dynamixel-sdk`` the driver uses, so the simulator checks the SDK (and our use of it) rather
than sharing its mistakes.

Frame layout (both directions)::

    FF FF FD 00 | ID | LEN_L LEN_H | INST | [ERR] PARAMS | CRC_L CRC_H

``LEN`` counts everything after itself (instruction, error byte of a status packet, stuffed
parameters, CRC). Inside INST..PARAMS every ``FF FF FD`` is followed by an extra ``FD`` so a
header cannot appear in the payload. The CRC is CRC-16 with polynomial 0x8005, initial value
0, no reflection, no final xor (catalogue name CRC-16/UMTS; check value 0xFEE8) over the whole
stuffed frame from the first ``FF``.
"""

from __future__ import annotations

from dataclasses import dataclass

HEADER = b"\xff\xff\xfd\x00"
BROADCAST_ID = 0xFE
MAX_ID = 0xFC

# Instructions
PING = 0x01
READ = 0x02
WRITE = 0x03
REBOOT = 0x08
STATUS = 0x55
SYNC_READ = 0x82
SYNC_WRITE = 0x83

# Error numbers carried in bits 0-6 of a status packet's ERR byte; bit 7 is the alert flag.
ERR_RESULT_FAIL = 1
ERR_INSTRUCTION = 2
ERR_CRC = 3
ERR_DATA_RANGE = 4
ERR_DATA_LENGTH = 5
ERR_DATA_LIMIT = 6
ERR_ACCESS = 7
ALERT_BIT = 0x80

_POLY = 0x8005


def _crc_table() -> tuple[int, ...]:
    table = []
    for byte in range(256):
        crc = byte << 8
        for _ in range(8):
            crc = ((crc << 1) ^ _POLY) if crc & 0x8000 else (crc << 1)
        table.append(crc & 0xFFFF)
    return tuple(table)


_TABLE = _crc_table()


def crc16(data: bytes, crc: int = 0) -> int:
    """CRC-16/UMTS of ``data`` (poly 0x8005, init 0, not reflected), continuing from ``crc``."""
    for byte in data:
        crc = ((crc << 8) & 0xFFFF) ^ _TABLE[((crc >> 8) ^ byte) & 0xFF]
    return crc


def stuff(body: bytes) -> bytes:
    """Insert an ``FD`` after every ``FF FF FD`` of ``body`` (instruction and parameters)."""
    out = bytearray()
    for i, byte in enumerate(body):
        out.append(byte)
        if byte == 0xFD and i >= 2 and body[i - 2 : i] == b"\xff\xff":
            out.append(0xFD)
    return bytes(out)


def unstuff(body: bytes) -> bytes:
    """Undo :func:`stuff`: drop the ``FD`` that follows every ``FF FF FD``."""
    out = bytearray()
    i = 0
    while i < len(body):
        out.append(body[i])
        if out[-3:] == b"\xff\xff\xfd" and i + 1 < len(body) and body[i + 1] == 0xFD:
            i += 2
        else:
            i += 1
    return bytes(out)


def _frame(dxl_id: int, body: bytes) -> bytes:
    stuffed = stuff(body)
    head = HEADER + bytes([dxl_id]) + (len(stuffed) + 2).to_bytes(2, "little")
    crc = crc16(head + stuffed)
    return head + stuffed + crc.to_bytes(2, "little")


def encode_instruction(dxl_id: int, instruction: int, params: bytes = b"") -> bytes:
    """A complete instruction packet, stuffed and with its CRC."""
    if not 0 <= dxl_id <= BROADCAST_ID or dxl_id in (0xFD,):
        raise ValueError(f"Dynamixel ID must be 0-252 or 254 (broadcast), got {dxl_id}")
    return _frame(dxl_id, bytes([instruction]) + params)


def encode_status(dxl_id: int, error: int, params: bytes = b"") -> bytes:
    """A complete status packet (instruction 0x55, then the error byte and parameters)."""
    return _frame(dxl_id, bytes([STATUS, error & 0xFF]) + params)


@dataclass(frozen=True)
class Packet:
    """One received frame.

    ``params`` are unstuffed and, for a status packet, exclude the error byte (in ``error``).
    ``crc_ok`` is False when the frame arrived complete but its CRC did not match.
    """

    dxl_id: int
    instruction: int
    params: bytes
    error: int | None = None
    crc_ok: bool = True


class PacketParser:
    """Incremental parser: feed it bytes as they arrive, get complete packets back.

    Garbage before a header is skipped; a frame with a bad CRC is returned with
    ``crc_ok=False`` (the device answers it with a CRC error) and parsing resumes after it.
    """

    MAX_LEN = 1024

    def __init__(self) -> None:
        self._buf = bytearray()

    def feed(self, data: bytes) -> list[Packet]:
        self._buf += data
        packets: list[Packet] = []
        while True:
            start = self._buf.find(HEADER)
            if start < 0:
                # Keep a possible partial header at the end.
                del self._buf[: max(len(self._buf) - 3, 0)]
                return packets
            del self._buf[:start]
            if len(self._buf) < 7:
                return packets
            length = int.from_bytes(self._buf[5:7], "little")
            if length < 3 or length > self.MAX_LEN:
                del self._buf[:1]  # not a real header; look for the next one
                continue
            total = 7 + length
            if len(self._buf) < total:
                return packets
            frame = bytes(self._buf[:total])
            del self._buf[:total]
            packets.append(_decode(frame))

    def reset(self) -> None:
        self._buf.clear()


def _decode(frame: bytes) -> Packet:
    crc_ok = crc16(frame[:-2]) == int.from_bytes(frame[-2:], "little")
    body = unstuff(frame[7:-2])
    inst = body[0]
    if inst == STATUS and len(body) >= 2:
        return Packet(frame[4], inst, body[2:], error=body[1], crc_ok=crc_ok)
    return Packet(frame[4], inst, body[1:], crc_ok=crc_ok)


def decode(frame: bytes) -> Packet:
    """Decode exactly one complete frame.

    Raises
    ------
    ValueError
        When ``frame`` is not one complete Protocol 2.0 frame.
    """
    packets = PacketParser().feed(frame)
    if len(packets) != 1:
        raise ValueError(
            f"expected one Dynamixel 2.0 frame, found {len(packets)} in {frame.hex(' ')}"
        )
    return packets[0]
