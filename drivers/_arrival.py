"""When to poll a stage for the end of a move (shared by the stage drivers).

A driver learns that a move has finished only by asking, so the time between the true end and
the poll that sees it is pure overhead; at a fixed 20 ms interval it averages 10 ms a move.
Polling fast for the whole move would load the bus and the worker threads for nothing. The
drivers therefore predict the end from the configured trapezoidal profile, poll at the coarse
interval while the move is surely under way (that still catches a stall or a fault early),
sleep exactly up to the predicted end, and poll at a fine interval from there on. A stage that
is slower than predicted costs a few more fine polls; one that is faster (a simulator running
faster than real time) is seen at the next coarse poll, as without a prediction. The
prediction is :func:`gonio.motion.move_time`, the formula the dry run times scans with.
"""

from __future__ import annotations

FINE_POLL_S = 0.002
"""Poll interval once the predicted end of a move has passed, seconds."""


def poll_delay(now: float, expected_end: float | None, coarse_s: float,
               fine_s: float = FINE_POLL_S) -> float:
    """Seconds to wait before the next completion poll.

    Parameters
    ----------
    now : float
        Present time, seconds (monotonic clock).
    expected_end : float or None
        Predicted end of the move on the same clock; None when unknown (homing), which
        polls at ``coarse_s`` throughout.
    coarse_s : float
        Interval while the move is predicted to run, seconds.
    fine_s : float
        Interval after the predicted end, seconds (``<= coarse_s`` for a useful schedule).

    Returns
    -------
    float
        ``coarse_s`` well before the end, the time left when the end is nearer than that,
        and ``fine_s`` once it has passed.
    """
    if expected_end is None:
        return coarse_s
    return min(coarse_s, max(fine_s, expected_end - now))
