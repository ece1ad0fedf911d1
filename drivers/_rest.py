"""Where a stage's last move came to rest (shared by the stage drivers).

A move with no approach side (``approach = "none"``, or no backlash overshoot) needs its start
position only to time the completion polls (:mod:`gonio.drivers._arrival`), so the position
the previous move came to rest at can stand in for the request that would read it: one round
trip fewer per move. It is trusted only while nothing else can have moved the axis: a move
that fails or is cancelled forgets it, and the drivers forget it on connect, close, stop,
home and fault clearing. A wrong guess costs a few completion polls, never a wrong arrival:
each driver confirms the arrival from the device.
"""

from __future__ import annotations

from collections.abc import Awaitable, Callable


class RestPosition:
    """The rest position of a stage's last move, and when it may replace a position read.

    Parameters
    ----------
    approach : {"positive", "negative", "none"}
        The stage's approach side.
    backlash_deg : float
        Its backlash overshoot, degrees. With an approach side and an overshoot, the start
        position decides whether an overshoot leg is needed, so it is always read.
    """

    def __init__(self, approach: str, backlash_deg: float) -> None:
        self._may_stand_in = approach == "none" or backlash_deg <= 0
        self.deg: float | None = None
        """Where the last move came to rest, degrees; None when unknown."""

    def forget(self) -> None:
        """Something else may have moved the axis (or the link was lost)."""
        self.deg = None

    async def start(self, read: Callable[[], Awaitable[float]]) -> float:
        """The position a move starts from, degrees: the last rest position where it may
        stand in, else ``read()`` (the driver's position request)."""
        if self.deg is not None and self._may_stand_in:
            return self.deg
        return await read()

    async def track(self, move: Awaitable[float]) -> float:
        """Await ``move`` (it returns the position reached, degrees), remember where it came
        to rest and return it; forget on any error or cancellation, then re-raise."""
        try:
            actual = await move
        except BaseException:
            self.deg = None
            raise
        self.deg = actual
        return actual
