"""Job states and the one table of allowed transitions.

Every state change of a job, whoever asks for it (the engine, the worker, a user through the
API, startup reconciliation), goes through :func:`check_transition`, so the lifecycle in
``docs/engine.md`` is enforced in exactly one place.

Lifecycle (docs/architecture.md, "Job lifecycle")::

    queued -> running <-> paused
    running -> suspended -> running           (a device fault with automatic resume)
    running -> reconstructing -> completed
    queued | running | paused | suspended | reconstructing -> failed | aborted
    running | paused | suspended -> halted    (emergency halt)
    failed -> completed                       (gonio jobs rebuild: failed while finishing,
                                               every reading stored)

A job found ``running``, ``paused``, ``suspended`` or ``reconstructing`` at startup (the process
died) keeps its state and is resumed from its last checkpoint, or moves to ``failed`` with the
reason when it cannot be resumed (see :meth:`gonio.store.JobStore.reconcile`).
"""

from __future__ import annotations

from collections.abc import Iterable
from enum import StrEnum


class JobState(StrEnum):
    """States of a scan job."""

    QUEUED = "queued"
    RUNNING = "running"
    PAUSED = "paused"
    SUSPENDED = "suspended"
    RECONSTRUCTING = "reconstructing"
    COMPLETED = "completed"
    FAILED = "failed"
    ABORTED = "aborted"
    HALTED = "halted"


Q, RUN, P, S, REC = (
    JobState.QUEUED,
    JobState.RUNNING,
    JobState.PAUSED,
    JobState.SUSPENDED,
    JobState.RECONSTRUCTING,
)
DONE, FAIL, AB, HALT = JobState.COMPLETED, JobState.FAILED, JobState.ABORTED, JobState.HALTED

TRANSITIONS: dict[JobState, frozenset[JobState]] = {
    # A queued job is cancelled by moving it to aborted; it has touched no hardware. One that
    # cannot start (its plan no longer fits the rig, the calibration no longer covers it)
    # fails without having run.
    Q: frozenset({RUN, FAIL, AB}),
    RUN: frozenset({P, S, REC, FAIL, AB, HALT}),
    # A paused job keeps its checkpoint; it can only go back to running or end.
    P: frozenset({RUN, FAIL, AB, HALT}),
    # Pausing a suspended job holds it after the fault clears instead of resuming.
    S: frozenset({RUN, P, FAIL, AB, HALT}),
    # Reconstruction touches no hardware, so a halt is not meaningful here, but an abort is.
    REC: frozenset({DONE, FAIL, AB}),
    DONE: frozenset(),
    # Only a job failed or aborted while it was being finished (from reconstructing), all its
    # readings stored: gonio jobs rebuild writes the result and completes it
    # (gonio.finishing.rebuild_result). Nothing is measured again.
    FAIL: frozenset({DONE}),
    AB: frozenset({DONE}),
    HALT: frozenset(),
}

ACTIVE_STATES: frozenset[JobState] = frozenset({RUN, P, S, REC})
"""States in which a job owns the rig (or its data is being turned into a result)."""

FINISHED_STATES: frozenset[JobState] = frozenset({DONE, FAIL, AB, HALT})
"""Terminal states: no job runs again from them (a job failed or aborted while finishing,
every reading stored, is completed by ``gonio jobs rebuild``, which measures nothing)."""

# User actions and the states they are accepted in. The engine performs the actual transition
# (a pause takes effect at the next checkpoint), so these say only when a request is legal.
ACTIONS: dict[str, frozenset[JobState]] = {
    "pause": frozenset({RUN, S}),
    "resume": frozenset({P}),
    "abort": frozenset({Q, RUN, P, S, REC}),
    "cancel": frozenset({Q}),
    "reorder": frozenset({Q}),
    "remove": frozenset({Q}) | FINISHED_STATES,
}


class IllegalTransition(ValueError):
    """A state change or user action that the lifecycle does not allow in the job's state."""

    def __init__(self, message: str, *, job_id: int | None = None, state: str | None = None):
        super().__init__(message)
        self.job_id = job_id
        self.state = state


def _names(states: frozenset[JobState]) -> str:
    return ", ".join(sorted(s.value for s in states)) or "no state"


def check_transition(current: str, new: str, job_id: int | None = None) -> JobState:
    """Return ``new`` as a :class:`JobState` if ``current -> new`` is allowed, else raise.

    Raises
    ------
    IllegalTransition
        With a message naming the job, both states and the states reachable from ``current``.
    """
    cur, nxt = JobState(current), JobState(new)
    if nxt not in TRANSITIONS[cur]:
        who = f"job {job_id}" if job_id is not None else "job"
        raise IllegalTransition(
            f"{who} cannot go from {cur.value} to {nxt.value}; from {cur.value} it can go to: "
            f"{_names(TRANSITIONS[cur])}",
            job_id=job_id,
            state=cur.value,
        )
    return nxt


def check_action(action: str, current: str, job_id: int | None = None) -> None:
    """Raise :class:`IllegalTransition` unless the user action is allowed in ``current``."""
    allowed = ACTIONS[action]
    cur = JobState(current)
    if cur not in allowed:
        who = f"job {job_id}" if job_id is not None else "job"
        raise IllegalTransition(
            f"cannot {action} {who}: it is {cur.value}; {action} is allowed only when the job "
            f"is {_names(allowed)}",
            job_id=job_id,
            state=cur.value,
        )


QUEUE_HOLD = "queue"
"""Name of the queue hold in the store's ``holds`` table (:meth:`gonio.store.JobStore.hold`):
an emergency halt's, or a job's that stops the queue on failure."""


def queue_wait(active: Iterable[tuple[int, str]], held: str | None,
               maintenance: str | None = None) -> str | None:
    """Why no queued job starts now, in words; None when the next one starts once the rig is
    free. One sentence for the API's ``waiting``, the lab page's queue and ``gonio jobs``.

    Parameters
    ----------
    active : ``(id, state)`` of the jobs that own the rig (running, paused, suspended,
        reconstructing), in id order
    held : why the queue is held (an emergency halt, a failed job that stops the queue), or
        None
    maintenance : the maintenance lock's reason while it is set (a daemon's), or None
    """
    if held is not None:
        return (f"the queue is held ({held}): queued jobs start once it is released "
                "(release on the lab page, gonio jobs --daemon URL release, or POST "
                "/api/v1/rig/release)")
    if maintenance is not None:
        return (f"{maintenance}: queued jobs start once it is lifted "
                "(DELETE /api/v1/maintenance)")
    for job_id, state in active:
        if state == JobState.PAUSED:
            return f"waits for job {job_id} (paused): resume or abort it"
        if state == JobState.SUSPENDED:
            return f"waits for job {job_id} (suspended until its device answers)"
    return None
