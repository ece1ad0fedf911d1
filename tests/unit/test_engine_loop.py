"""The engine's own loop: work handed to it runs on its thread, and closing it ends the thread
and cancels what still runs there."""

from __future__ import annotations

import asyncio
import sys
import threading
from collections.abc import Iterator

import pytest

from gonio.engine_loop import SWITCH_INTERVAL_S, EngineLoop


@pytest.fixture
def engine_loop() -> Iterator[EngineLoop]:
    el = EngineLoop(name="test-engine")
    el.start()
    yield el
    el.close()


def test_a_loop_that_is_not_started_says_so() -> None:
    el = EngineLoop()
    assert not el.running and not el.in_loop()
    with pytest.raises(RuntimeError, match=r"not running; call start\(\) first"):
        _ = el.loop
    el.close()  # closing a loop never started is harmless


def test_coroutines_run_on_the_engine_thread(engine_loop: EngineLoop) -> None:
    async def where() -> tuple[str, bool]:
        return threading.current_thread().name, engine_loop.in_loop()

    assert engine_loop.submit(where()).result(timeout=30) == ("test-engine", True)
    # from another loop, awaited
    assert asyncio.run(engine_loop.run(where())) == ("test-engine", True)
    assert not engine_loop.in_loop()


def test_run_on_the_engine_loop_itself_awaits_directly(engine_loop: EngineLoop) -> None:
    async def inner() -> int:
        return 7

    async def outer() -> int:
        return await engine_loop.run(inner())

    assert engine_loop.submit(outer()).result(timeout=30) == 7


def test_call_runs_the_function_on_the_engine_thread(engine_loop: EngineLoop) -> None:
    seen: list[str] = []
    done = threading.Event()

    def note(x: str) -> None:
        seen.append(f"{x}@{threading.current_thread().name}")
        done.set()

    engine_loop.call(note, "a")
    assert done.wait(30)
    assert seen == ["a@test-engine"]


def test_an_exception_reaches_the_caller(engine_loop: EngineLoop) -> None:
    async def fail() -> None:
        raise ValueError("device said no")

    with pytest.raises(ValueError, match="device said no"):
        asyncio.run(engine_loop.run(fail()))


def test_close_cancels_pending_work_and_restores_the_switch_interval() -> None:
    before = sys.getswitchinterval()
    el = EngineLoop()
    el.start()
    el.start()  # a second start does nothing
    assert el.running
    assert sys.getswitchinterval() == pytest.approx(min(before, SWITCH_INTERVAL_S))
    started, cancelled = threading.Event(), threading.Event()

    async def forever() -> None:
        started.set()
        try:
            await asyncio.sleep(3600)
        except asyncio.CancelledError:
            cancelled.set()
            raise

    future = el.submit(forever())
    assert started.wait(30)
    el.close()
    assert cancelled.is_set() and future.cancelled()
    assert not el.running
    assert sys.getswitchinterval() == pytest.approx(before)


def test_running_in_tells_the_loop_the_caller_runs_on() -> None:
    """Inside a loop's own coroutine: that loop, not another; outside any loop: none."""
    from gonio.engine_loop import running_in

    other = asyncio.new_event_loop()
    try:
        async def check() -> tuple[bool, bool]:
            here = asyncio.get_running_loop()
            return running_in(here), running_in(other)

        assert asyncio.run(check()) == (True, False)
        assert not running_in(other)
    finally:
        other.close()
