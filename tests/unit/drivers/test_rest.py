"""The rest position the stage drivers share: when it replaces a position read, and when it is
forgotten (a failed or cancelled move, an explicit forget)."""

from __future__ import annotations

import asyncio

import pytest

from gonio.drivers._rest import RestPosition


class Axis:
    """An axis whose position reads are counted; moves return a given rest position."""

    def __init__(self, at: float) -> None:
        self.at = at
        self.reads = 0

    async def read(self) -> float:
        self.reads += 1
        return self.at

    async def move(self, to: float) -> float:
        await asyncio.sleep(0)
        self.at = to
        return to


def test_without_an_approach_side_the_last_rest_position_stands_in_for_a_read() -> None:
    async def main() -> None:
        axis, rest = Axis(5.0), RestPosition("none", 0.5)
        assert await rest.start(axis.read) == 5.0  # nothing known yet: read
        assert await rest.track(axis.move(30.0)) == 30.0
        axis.at = 31.0  # where a read would say it is now
        assert await rest.start(axis.read) == 30.0
        assert axis.reads == 1

    asyncio.run(main())


def test_with_no_overshoot_the_rest_position_stands_in_whatever_the_side() -> None:
    async def main() -> None:
        axis, rest = Axis(0.0), RestPosition("positive", 0.0)
        await rest.track(axis.move(12.0))
        assert await rest.start(axis.read) == 12.0
        assert axis.reads == 0

    asyncio.run(main())


def test_with_an_approach_side_and_an_overshoot_the_start_is_always_read() -> None:
    async def main() -> None:
        axis, rest = Axis(0.0), RestPosition("positive", 0.5)
        await rest.track(axis.move(12.0))
        axis.at = 11.0
        assert await rest.start(axis.read) == 11.0
        assert axis.reads == 1

    asyncio.run(main())


def test_a_failed_move_forgets_the_rest_position() -> None:
    async def fails() -> float:
        raise OSError("port lost")

    async def main() -> None:
        axis, rest = Axis(7.0), RestPosition("none", 0.0)
        await rest.track(axis.move(20.0))
        with pytest.raises(OSError, match="port lost"):
            await rest.track(fails())
        assert rest.deg is None
        assert await rest.start(axis.read) == 20.0  # read again
        assert axis.reads == 1

    asyncio.run(main())


def test_a_cancelled_move_forgets_the_rest_position() -> None:
    async def main() -> None:
        axis, rest = Axis(0.0), RestPosition("none", 0.0)
        await rest.track(axis.move(20.0))
        task = asyncio.create_task(rest.track(asyncio.sleep(10.0, result=40.0)))
        await asyncio.sleep(0)
        task.cancel()
        with pytest.raises(asyncio.CancelledError):
            await task
        assert rest.deg is None

    asyncio.run(main())


def test_forget_makes_the_next_start_read() -> None:
    async def main() -> None:
        axis, rest = Axis(0.0), RestPosition("none", 0.0)
        await rest.track(axis.move(20.0))
        rest.forget()
        axis.at = 25.0  # moved by someone else (a stop, a home)
        assert await rest.start(axis.read) == 25.0

    asyncio.run(main())
