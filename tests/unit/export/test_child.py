"""The export fits of a daemon run in an interpreter of their own (gonio.export.child)."""

from __future__ import annotations

import logging
import os

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
