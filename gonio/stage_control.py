"""Manual stage commands: commissioning (the zero at the holder's mark) and loading specimens.

:class:`StageControl` moves, homes, stops and clears the stage by hand, refused while a job is
active (``stop`` excepted), and holds the queue for the command's duration so no job starts
under a manual move. It sees the queue only through :class:`QueueHold` (the worker is one) and
the rig through an async getter: it runs wherever its caller awaits it (the service runs it on
the engine loop, where the devices live).
"""

from __future__ import annotations

from collections.abc import Awaitable, Callable
from typing import Any, Protocol

from gonio import hal
from gonio.motion import StageMoveError
from gonio.rigdescription import RigDescription
from gonio.service_models import Conflict, DeviceError, Event, JobInfo, StageRequest, StageState


class QueueHold(Protocol):
    """The part of the queue a manual command needs: hold it for a moment, then let it go."""

    @property
    def held(self) -> str | None:
        """Why the queue takes no new job, or None."""

    def hold(self, reason: str, durable: bool = True) -> None:
        """Take no new job until :meth:`release`."""

    def release(self) -> None:
        """Take queued jobs again."""


def busy_message(job_id: int, state: str) -> str:
    """Why a manual stage command is refused while job ``job_id`` is active, and what frees the
    stage: only its end (or an abort). A paused job still holds it (it resumes at its
    checkpoint), so "pause it" is no advice; a reconstructing job moves nothing but keeps the
    stage until its result is written."""
    if state == "paused":
        return (f"job {job_id} is paused: it still holds the stage (it resumes at its "
                "checkpoint); resume it and wait for it to end, or abort it, before moving the "
                "stage by hand")
    if state == "reconstructing":
        return (f"job {job_id} is reconstructing: it moves the stage no more but holds it until "
                "its result is written (seconds; minutes when a basis must be built first); "
                "wait for it, or abort it, before moving the stage by hand")
    return (f"job {job_id} is {state}: the stage is in use; wait for the job to end, or abort "
            "it, before moving the stage by hand (a paused job still holds the stage)")


class StageControl:
    """Manual commands to one rig's stage.

    Parameters
    ----------
    desc : RigDescription
        The stage's travel limits.
    get_rig : async callable returning the connected rig
    queue : QueueHold
        Held while a command runs (unless held already).
    active_job : callable returning the active job, or None
        A command other than ``stop`` is refused while there is one.
    record_event : callable storing an event ``(type, data)`` for every subscriber
    """

    def __init__(self, desc: RigDescription, get_rig: Callable[[], Awaitable[hal.Rig]],
                 queue: QueueHold, active_job: Callable[[], JobInfo | None],
                 record_event: Callable[[str, dict[str, Any]], Event]) -> None:
        self.desc = desc
        self._get_rig = get_rig
        self._queue = queue
        self._active_job = active_job
        self._record_event = record_event
        # Stop commands sent so far: a move or home that a stop cut short ends as asked, not
        # as a fault (the driver reports a stage stopped short of its target as a stall).
        self._stops = 0

    async def command(self, request: StageRequest) -> StageState:
        """Run one manual stage command and return the stage state after it.

        The queue is held for the duration so no job starts under a manual move.

        Raises
        ------
        Conflict
            A job is active (``stop`` excepted: stopping is always allowed).
        StageMoveError
            A move without ``angle_deg`` or outside the stage's travel limits.
        DeviceError
            The stage reported a fault or stopped answering.
        """
        if request.action == "move":
            lo, hi = self.desc.stage_min_deg, self.desc.stage_max_deg
            if request.angle_deg is None:
                raise StageMoveError("a stage move needs angle_deg (degrees)")
            if not lo <= request.angle_deg <= hi:
                raise StageMoveError(
                    f"angle_deg {request.angle_deg:g} is outside the stage's travel limits "
                    f"[{lo:g}, {hi:g}] deg (min_deg/max_deg in the rig config)")
        active = self._active_job()
        if active is not None and request.action != "stop":
            raise Conflict(busy_message(active.id, active.state.value))
        was_held = self._queue.held is not None
        manual = f"manual stage command: {request.action}"
        if not was_held:
            # Only for the command's duration: not a decision to outlive a crash.
            self._queue.hold(manual, durable=False)
        if request.action == "stop":
            self._stops += 1
        note = None
        try:
            rig = await self._get_rig()
            stage = rig.stage
            # Counted from here, as the command goes to the stage: a stop sent while the rig
            # was still connecting came before the move and does not excuse its stall.
            stops = self._stops
            try:
                if request.action == "move":
                    assert request.angle_deg is not None
                    await stage.move_to(request.angle_deg)
                elif request.action == "home":
                    await stage.home()
                elif request.action == "stop":
                    await stage.stop()
                else:
                    await stage.clear_faults()
            except hal.DeviceFault:
                if request.action not in ("move", "home") or self._stops == stops:
                    raise
                note = "stopped by a stop command before it ended"
            st = await hal.status_at_rest(stage)
        except hal.DeviceFault as exc:
            raise DeviceError(f"stage {request.action} failed: {exc}") from exc
        finally:
            if not was_held and self._queue.held == manual:  # not a halt that came meanwhile
                self._queue.release()
        if note is not None:
            target = "" if request.angle_deg is None else f", short of {request.angle_deg:g} deg"
            note = f"{note}: at {st.position_deg:.3f} deg{target}"
        self._record_event("stage", {"action": request.action, "angle_deg": request.angle_deg,
                                     "position_deg": st.position_deg,
                                     **({"note": note} if note else {})})
        return StageState(position_deg=st.position_deg, moving=st.moving, homed=st.homed,
                          faults=list(st.faults), note=note)

    async def status(self) -> StageState:
        """Where the stage is, whether it moves, is homed, has faults (connects if needed).

        Raises
        ------
        DeviceError
            The stage does not answer or the rig cannot be connected.
        """
        try:
            rig = await self._get_rig()
            st = await rig.stage.status()
        except (hal.DeviceFault, OSError) as exc:
            raise DeviceError(f"stage status failed: {exc}") from exc
        return StageState(position_deg=st.position_deg, moving=st.moving, homed=st.homed,
                          faults=list(st.faults))
