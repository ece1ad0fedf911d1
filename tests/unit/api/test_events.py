"""The event stream's encoding (the SSE format of the HTML standard) and its life: heartbeats
while idle, the end of the events, a daemon shutdown. Over loopback: tests/system/api/."""

from __future__ import annotations

import asyncio
import json
import threading
from collections.abc import AsyncIterator
from types import SimpleNamespace
from typing import Any

from gonio.api.events import RETRY_MS, StreamCloser, format_event, sse_stream


def ev(seq: int, data: Any = None, **kw: Any) -> SimpleNamespace:
    return SimpleNamespace(seq=seq, type="job_state", job_id=3, data=data, **kw)


def test_an_event_is_one_message_with_its_seq_as_id() -> None:
    raw = format_event(ev(12, {"state": "running", "note": "a\nb"}, time=1.5))
    text = raw.decode()
    # SSE: "id:" and "data:" fields, one data line (no raw newline inside), a blank line ends it
    lines = text.split("\n")
    assert lines[0] == "id: 12" and lines[1].startswith("data: ") and lines[2:] == ["", ""]
    assert json.loads(lines[1][len("data: "):]) == {
        "seq": 12, "type": "job_state", "job_id": 3, "time": 1.5,
        "data": {"state": "running", "note": "a\nb"}}


def test_an_event_without_a_time_and_with_odd_data() -> None:
    payload = json.loads(format_event(ev(1, {"path": object}))[len("id: 1\ndata: "):])
    assert payload["time"] is None and payload["data"]["path"] == str(object)


async def _collect(stream: AsyncIterator[bytes], n: int | None = None) -> list[bytes]:
    out = []
    async for chunk in stream:
        out.append(chunk)
        if n is not None and len(out) == n:
            break
    return out


def test_the_stream_sets_the_retry_then_sends_each_event_and_ends_with_them() -> None:
    async def events() -> AsyncIterator[Any]:
        yield ev(1)
        yield ev(2)

    out = asyncio.run(_collect(sse_stream(events(), heartbeat_s=30)))
    assert out[0] == f"retry: {RETRY_MS}\n\n".encode()
    assert [o.split(b"\n")[0] for o in out[1:]] == [b"id: 1", b"id: 2"]


def test_an_idle_stream_sends_keep_alive_comments_without_losing_the_next_event() -> None:
    async def run() -> list[bytes]:
        go = asyncio.Event()
        closed = []

        async def events() -> AsyncIterator[Any]:
            try:
                await go.wait()
                yield ev(5)
            finally:
                closed.append(True)

        stream = sse_stream(events(), heartbeat_s=0.01)
        out = [await stream.__anext__(), await stream.__anext__(), await stream.__anext__()]
        go.set()
        async for chunk in stream:
            out.append(chunk)
            if chunk.startswith(b"id:"):
                break
        await stream.aclose()
        assert closed == [True]  # the source was closed once, not per heartbeat
        return out

    out = asyncio.run(run())
    assert out[1] == out[2] == b": keep-alive\n\n"  # an SSE comment line
    assert out[-1].startswith(b"id: 5\n")


def test_closing_ends_every_open_stream() -> None:
    async def run() -> list[bytes]:
        closer = StreamCloser()

        async def never() -> AsyncIterator[Any]:
            await asyncio.Event().wait()
            yield ev(0)

        stream = sse_stream(never(), heartbeat_s=30, closing=closer.event())
        first = await stream.__anext__()
        # from another thread, as a signal handler or the shutdown path does
        threading.Thread(target=closer.close).start()
        return [first, *await asyncio.wait_for(_collect(stream), 30)]

    assert asyncio.run(run()) == [f"retry: {RETRY_MS}\n\n".encode()]


def test_a_stream_opened_after_close_ends_at_once() -> None:
    async def run() -> bool:
        closer = StreamCloser()
        closer.close()
        return closer.event().is_set()

    assert asyncio.run(run())
