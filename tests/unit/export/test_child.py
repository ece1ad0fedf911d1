"""The export fits of a daemon run in an interpreter of their own (gonio.export.child)."""

from __future__ import annotations

import logging
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from gonio.export import ExportError
from gonio.export import child as export_child


def _pid() -> int:
    return os.getpid()


def _refuse(reason: str) -> None:
    raise ExportError(reason)


def _die_unless_in(pid: int) -> str:
    """Ends any process but ``pid`` without an answer, as a killed child would."""
    if os.getpid() != pid:
        os._exit(3)
    return "fitted here"


@pytest.fixture
def bounded(monkeypatch: pytest.MonkeyPatch) -> None:
    """As in ``gonio serve``, whose heap gonio.heap.bound_heap fixed."""
    monkeypatch.setattr(export_child, "heap_bounded", lambda: True)


def test_without_a_bounded_heap_the_fits_run_where_they_are_asked(
        monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(export_child, "heap_bounded", lambda: False)
    assert export_child.run_fits(_pid) == os.getpid()


def test_with_a_bounded_heap_they_run_in_another_process(bounded: None) -> None:
    assert export_child.run_fits(_pid) != os.getpid()


def test_an_export_error_in_the_child_reaches_the_caller_with_its_reason(
        bounded: None) -> None:
    with pytest.raises(ExportError, match="a calibration job's result"):
        export_child.run_fits(_refuse, "a calibration job's result has no BRDF")


def test_a_child_that_dies_leaves_the_fits_to_this_process_and_says_so(
        bounded: None, caplog: pytest.LogCaptureFixture) -> None:
    with caplog.at_level(logging.WARNING, logger="gonio.export"):
        assert export_child.run_fits(_die_unless_in, os.getpid()) == "fitted here"
    assert "fitting in the daemon" in caplog.text


def sleep_reporting(path: str) -> None:
    """Writes this process's id to ``path``, then fits for ten minutes (a killed daemon's
    child would sit on this for good)."""
    with open(path, "w") as f:
        f.write(str(os.getpid()))
    time.sleep(600)


KILLED_DAEMON = """
import sys
from gonio.export import child
child.heap_bounded = lambda: True  # as in gonio serve
from tests.unit.export.test_child import sleep_reporting
child.run_fits(sleep_reporting, sys.argv[1])
"""


def _ended(pid: int) -> bool:
    """Gone, or a zombie waiting for whoever adopted it to reap it (it runs nothing)."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except (FileNotFoundError, ProcessLookupError):
        return True
    return stat.rsplit(")", 1)[1].split()[0] == "Z"


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="reads /proc (Linux)")
def test_the_fits_process_ends_when_the_daemon_is_killed(tmp_path: Path) -> None:
    """kill -9 of a daemon whose export fits ran left their process behind for good (a few
    hundred MB blocked on a pipe nobody reads); it now ends within seconds."""
    reported = tmp_path / "child.pid"
    root = Path(__file__).resolve().parents[3]
    daemon = subprocess.Popen([sys.executable, "-c", KILLED_DAEMON, str(reported)], cwd=root)
    try:
        deadline = time.monotonic() + 120
        while not reported.is_file() or not reported.read_text():
            assert daemon.poll() is None, "the stand-in daemon ended before its fits started"
            assert time.monotonic() < deadline, "the fits' process never started"
            time.sleep(0.1)
        child_pid = int(reported.read_text())
        assert child_pid != daemon.pid and not _ended(child_pid)
    finally:
        daemon.send_signal(signal.SIGKILL)
        daemon.wait()
    deadline = time.monotonic() + 60
    try:
        while not _ended(child_pid):
            assert time.monotonic() < deadline, \
                f"the fits' process {child_pid} outlived its daemon"
            time.sleep(0.2)
    finally:
        if not _ended(child_pid):  # failed: leave no ten-minute sleeper behind
            os.kill(child_pid, signal.SIGKILL)
