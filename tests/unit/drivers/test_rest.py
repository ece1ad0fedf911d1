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


@pytest.mark.parametrize(("approach", "backlash_deg", "stands_in"), [
    ("none", 0.5, True),  # no approach side: the overshoot is never used
    ("positive", 0.0, True),  # no overshoot, whatever the side
    ("positive", 0.5, False),  # the start decides whether an overshoot leg is needed
    ("negative", 0.2, False),
])
def test_the_rest_position_stands_in_for_a_read_only_without_an_overshoot(
        approach: str, backlash_deg: float, stands_in: bool) -> None:
    async def main() -> None:
        axis, rest = Axis(5.0), RestPosition(approach, backlash_deg)
        assert await rest.start(axis.read) == 5.0  # nothing known yet: read
        assert await rest.track(axis.move(30.0)) == 30.0
        axis.at = 31.0  # where a read would say it is now
        assert await rest.start(axis.read) == (30.0 if stands_in else 31.0)
        assert axis.reads == (1 if stands_in else 2)

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
