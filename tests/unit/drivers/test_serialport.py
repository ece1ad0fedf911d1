"""gonio.drivers._serialport: a port that cannot be opened, said once and in words."""

from __future__ import annotations

import errno
import os

import pytest
import serial

from gonio.drivers._serialport import lock_refused, open_failure

PORT = "/dev/ttyUSB0"


def _pyserial(code: int) -> serial.SerialException:
    """The exception pyserial raises when ``open`` fails with ``code`` (serialposix.py)."""
    inner = OSError(code, os.strerror(code), PORT)
    return serial.SerialException(code, f"could not open port {PORT}: {inner}")


@pytest.mark.parametrize(("code", "words"), [
    (errno.ENOENT, "does not exist"),
    (errno.EACCES, "no permission to open"),
    (errno.EBUSY, "is busy"),
    (errno.EIO, "has no device behind it any more"),
    (errno.ETIMEDOUT, "connection timed out"),
])
def test_each_error_number_is_said_in_words_naming_the_port_once(code: int,
                                                                 words: str) -> None:
    said = open_failure(PORT, _pyserial(code))
    assert words in said, said
    assert "Errno" not in said and said.count(PORT) == 1, said


def test_a_url_pyserial_cannot_read_keeps_its_reason() -> None:
    said = open_failure("nosuchscheme://x", ValueError("invalid URL, protocol 'nosuchscheme' "
                                                       "not known"))
    assert said == "cannot open 'nosuchscheme://x': invalid URL, protocol 'nosuchscheme' not known"


def test_a_held_port_names_it_and_says_what_to_do() -> None:
    said = lock_refused(PORT)
    assert said.count(PORT) == 1 and "close it" in said and "Errno" not in said
