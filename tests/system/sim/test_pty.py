"""The simulators' pseudo-terminal: raw bytes both ways, as a serial driver opens it."""

from __future__ import annotations

import os
import select
import threading

from gonio.sim.pty import PtyTransport


def _read(fd: int, n: int, timeout_s: float = 30.0) -> bytes:
    out = b""
    while len(out) < n:
        ready, _, _ = select.select([fd], [], [], timeout_s)
        assert ready, f"no reply within {timeout_s} s (got {out!r})"
        out += os.read(fd, n - len(out))
    return out


def test_bytes_reach_the_handler_and_its_reply_comes_back_unchanged() -> None:
    got: list[bytes] = []

    def handler(data: bytes) -> bytes:
        got.append(data)
        return data[::-1]

    pty = PtyTransport(handler)
    try:
        assert pty.port.startswith("/dev/")
        fd = os.open(pty.port, os.O_RDWR | os.O_NOCTTY)
        try:
            # a Dynamixel-like binary packet and Zaber's CR: a raw terminal translates neither
            # and echoes nothing
            packet = b"\xff\xff\xfd\x00\x01\x03\x00\x01\r\x03"
            os.write(fd, packet)
            assert _read(fd, len(packet)) == packet[::-1]
            assert b"".join(got) == packet
        finally:
            os.close(fd)
    finally:
        pty.close()
        pty.close()  # twice is safe


def test_write_sends_unprompted_bytes_and_an_empty_reply_sends_nothing() -> None:
    calls = threading.Event()

    def handler(data: bytes) -> bytes:
        calls.set()
        return b""

    pty = PtyTransport(handler)
    try:
        fd = os.open(pty.port, os.O_RDWR | os.O_NOCTTY)
        try:
            os.write(fd, b"x")
            assert calls.wait(30)
            pty.write(b"@01 0 OK IDLE -- 0\r\n")
            assert _read(fd, 20) == b"@01 0 OK IDLE -- 0\r\n"
        finally:
            os.close(fd)
    finally:
        pty.close()
