"""The daemon's log filters: keys never reach the access log, routine reads are dropped,
pymodbus' frame dumps become one-line warnings."""

from __future__ import annotations

import logging

import pytest

from gonio.logfilters import (
    ACCESS_LOGGER,
    PYMODBUS_LOGGER,
    PymodbusFrameFilter,
    QueryKeyRedactor,
    RoutineRequestFilter,
    install,
    redact_query,
)


@pytest.mark.parametrize(("path", "expected"), [
    ("/api/v1/jobs", "/api/v1/jobs"),
    ("/api/v1/jobs?since=3", "/api/v1/jobs?since=3"),
    ("/api/v1/jobs?api_key=abc&since=3", "/api/v1/jobs?api_key=[redacted]&since=3"),
    ("/x?X-API-Key=abc", "/x?X-API-Key=[redacted]"),
    ("/x?token=abc&key=d", "/x?token=[redacted]&key=[redacted]"),
    ("/x?TOKEN=t&Password=p&x-auth=a&client_secret=s",
     "/x?TOKEN=[redacted]&Password=[redacted]&x-auth=[redacted]&client_secret=[redacted]"),
    ("/x?sometoken", "/x?[redacted]"),  # not name=value: it may be the key itself
    ("/x?s3cr3t", "/x?[redacted]"),
    ("/x?a=1&s3cr3t&b=2", "/x?a=1&[redacted]&b=2"),
    ("/x?&&", "/x?[redacted]"),
    ("/x?a=1=2", "/x?a=1%3D2"),
    ("/x?key=", "/x?key=[redacted]"),
    ("/x?name=a%20b", "/x?name=a%20b"),
])
def test_redact_query(path: str, expected: str) -> None:
    assert redact_query(path) == expected


def _access(method: str, path: str, status: int) -> logging.LogRecord:
    """A record shaped as uvicorn's access log writes it."""
    return logging.LogRecord(ACCESS_LOGGER, logging.INFO, "h.py", 1,
                             '%s - "%s %s HTTP/%s" %d',
                             ("127.0.0.1:5", method, path, "1.1", status), None)


def test_the_redactor_rewrites_the_access_record_and_keeps_it() -> None:
    rec = _access("GET", "/api/v1/events?api_key=s3cret", 200)
    assert QueryKeyRedactor().filter(rec)
    assert "s3cret" not in rec.getMessage()
    assert rec.getMessage() == '127.0.0.1:5 - "GET /api/v1/events?api_key=[redacted] HTTP/1.1" 200'


def test_the_redactor_rewrites_a_plain_message() -> None:
    rec = logging.LogRecord("x", logging.INFO, "h.py", 1, "GET /a?key=k1 done", None, None)
    assert QueryKeyRedactor().filter(rec)
    assert rec.getMessage() == "GET /a?key=[redacted] done"


@pytest.mark.parametrize(("method", "status", "kept"), [
    ("GET", 200, False), ("HEAD", 304, False), ("GET", 404, True), ("GET", 500, True),
    ("POST", 201, True), ("DELETE", 204, True),
])
def test_routine_reads_are_dropped(method: str, status: int, kept: bool) -> None:
    assert RoutineRequestFilter().filter(_access(method, "/api/v1/jobs/1", status)) is kept


def test_a_pymodbus_error_becomes_a_one_line_warning() -> None:
    rec = logging.LogRecord(PYMODBUS_LOGGER, logging.ERROR, "p.py", 1,
                            "unable to decode %s\n>>>>> send: 0x1 0x2\n<<<<< recv: 0x3",
                            ("response",), None)
    assert PymodbusFrameFilter().filter(rec)
    assert rec.levelno == logging.WARNING and rec.levelname == "WARNING"
    assert rec.getMessage() == "unable to decode response (pymodbus; the driver reports the fault)"


def test_a_pymodbus_id_mismatch_keeps_its_words_not_its_frames() -> None:
    frame = logging.LogRecord(PYMODBUS_LOGGER, logging.ERROR, "p.py", 1,
                              "ERROR: request ask for id=2 but got id=1, Skipping.\n"
                              ">>>>> send: 0x0 0x1 0x0 0x0 0x0 0x6\n>>>>> recv: 0x0 0x1", None,
                              None)
    assert PymodbusFrameFilter().filter(frame)
    assert frame.levelno == logging.WARNING
    assert "0x0" not in frame.getMessage() and "got id=1" in frame.getMessage()


def test_a_pymodbus_server_traceback_becomes_its_last_line() -> None:
    # `gonio sim` printed a 14-line traceback for each request to a device id it does not
    # have (a rig config with devices added by `gonio rig apply-design`).
    trace = ("Datastore unable to fulfill request: 0; Traceback (most recent call last):\n"
             '  File "requesthandler.py", line 92, in handle_request\n'
             "    response = await self.last_pdu.datastore_update(\n"
             "               ^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^\n"
             "KeyError: 0\n")
    rec = logging.LogRecord(PYMODBUS_LOGGER, logging.ERROR, "p.py", 1, trace, None, None)
    assert PymodbusFrameFilter().filter(rec)
    assert rec.getMessage() == ("Datastore unable to fulfill request: 0 (KeyError: 0) "
                                "(pymodbus; the driver reports the fault)")


def test_the_same_pymodbus_error_again_within_the_window_is_dropped() -> None:
    """A silent sensor: pymodbus said "No response received after 0 retries ..." at every
    poll, 13 times in one outage. Once per window; a different line, or the same one after
    the window, passes."""
    filt = PymodbusFrameFilter()

    def rec(msg: str, at: float) -> logging.LogRecord:
        r = logging.LogRecord(PYMODBUS_LOGGER, logging.ERROR, "p.py", 1, msg, None, None)
        r.created = at
        return r

    silent = "No response received after 0 retries, continue with next request"
    assert filt.filter(rec(silent, 1000.0))
    assert not filt.filter(rec(silent, 1001.0))
    assert not filt.filter(rec(silent, 1000.0 + filt.REPEAT_WINDOW_S - 1))
    assert filt.filter(rec("Connection lost", 1002.0))
    assert filt.filter(rec(silent, 1003.0))  # not the last line passed: said again
    assert filt.filter(rec(silent, 1003.0 + filt.REPEAT_WINDOW_S + 1))
    # Debug records are left alone (frames at debug level differ anyway).
    debug = logging.LogRecord(PYMODBUS_LOGGER, logging.DEBUG, "p.py", 1, silent, None, None)
    assert filt.filter(debug) and filt.filter(debug)


@pytest.mark.parametrize("level", [logging.DEBUG, logging.WARNING, logging.ERROR])
def test_pymodbus_repeat_lines_are_dropped(level: int) -> None:
    # pymodbus logs "Repeating...." at the level of the line it repeats: it adds nothing.
    rec = logging.LogRecord(PYMODBUS_LOGGER, level, "p.py", 1, "Repeating....", None, None)
    assert PymodbusFrameFilter().filter(rec) is False


def test_a_pymodbus_debug_record_is_left_alone() -> None:
    rec = logging.LogRecord(PYMODBUS_LOGGER, logging.DEBUG, "p.py", 1, "frame %s", ("0x1",), None)
    assert PymodbusFrameFilter().filter(rec)
    assert rec.levelno == logging.DEBUG and rec.getMessage() == "frame 0x1"


@pytest.fixture
def clean_loggers() -> object:
    names = (ACCESS_LOGGER, PYMODBUS_LOGGER)
    saved = {n: list(logging.getLogger(n).filters) for n in names}
    for n in names:
        logging.getLogger(n).filters.clear()
    yield None
    for n in names:
        logging.getLogger(n).filters[:] = saved[n]


@pytest.mark.usefixtures("clean_loggers")
def test_install_attaches_each_filter_once() -> None:
    install()
    install()
    access = [type(f) for f in logging.getLogger(ACCESS_LOGGER).filters]
    assert sorted(c.__name__ for c in access) == ["QueryKeyRedactor", "RoutineRequestFilter"]
    assert [type(f) for f in logging.getLogger(PYMODBUS_LOGGER).filters] == [PymodbusFrameFilter]


@pytest.mark.usefixtures("clean_loggers")
def test_install_without_quiet_reads_keeps_the_reads() -> None:
    install(quiet_reads=False)
    assert [type(f) for f in logging.getLogger(ACCESS_LOGGER).filters] == [QueryKeyRedactor]


@pytest.mark.usefixtures("clean_loggers")
def test_the_command_line_hides_pymodbus_warnings_and_keeps_its_errors() -> None:
    from gonio.logfilters import install_pymodbus

    parent = logging.getLogger("pymodbus")
    before = parent.level
    try:
        install_pymodbus()
        install_pymodbus()
        log = logging.getLogger(PYMODBUS_LOGGER)
        assert [type(f) for f in log.filters] == [PymodbusFrameFilter]
        assert not log.isEnabledFor(logging.WARNING) and log.isEnabledFor(logging.ERROR)
    finally:
        parent.setLevel(before)
