"""A plan's fault policy applied: when a device fault suspends a job, and when it fails it.

:class:`~gonio.plans.models.FaultPolicy` holds a plan's settings; a :class:`Suspender` made of
them decides, for each fault at a stage angle and each failed recovery, whether the job waits
and tries again or fails, and what the job's events and failure reason say. The engine carries
the decisions out (suspends, switches the lights off, sleeps, recovers the device); it holds
no rule of its own.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from gonio import hal
from gonio.plans.models import FaultPolicy


@dataclass(frozen=True)
class Trouble:
    """The first fault at an angle and when it happened (monotonic seconds)."""

    first: hal.DeviceFault
    since: float

    def began_as(self, last: hal.DeviceFault) -> str:
        """``"; it began as: ..."`` when the first fault says something else than ``last``."""
        if str(self.first) == str(last):
            return ""
        return f"; it began as: {self.first} (code {self.first.code})"


@dataclass(frozen=True)
class AfterRecovery:
    """What follows a recovery that failed with a fault.

    ``failure``: the job fails with this reason (None: it waits and tries again);
    ``event``: the ``fault`` event to record first, if any; ``announced``: the waiting for a
    silent device has been announced (pass it to the next call).
    """

    failure: str | None
    event: dict[str, Any] | None
    announced: bool


class Suspender:
    """The rules of a plan's :class:`~gonio.plans.models.FaultPolicy`.

    More than ``max_retries`` consecutive failures at one angle fail the job, except for a
    device that does not answer at all (:class:`gonio.hal.DeviceUnavailable`): it is waited
    for up to ``wait_for_device_s`` from the first fault. An unrecoverable fault fails the job
    at once. ``clock`` gives monotonic seconds (tests may pass their own).
    """

    def __init__(self, policy: FaultPolicy,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.policy = policy
        self._clock = clock

    def trouble(self, fault: hal.DeviceFault) -> Trouble:
        """The record of ``fault`` as the first one at an angle, from now."""
        return Trouble(fault, self._clock())

    def refusal(self, fault: hal.DeviceFault, retries: int, trouble: Trouble) -> str | None:
        """The job's failure reason if ``fault`` (the ``retries``-th consecutive failure at
        the angle) fails it rather than suspending it; None to suspend and recover."""
        if not fault.recoverable:
            return self._unrecoverable(fault, trouble)
        if retries > self.policy.max_retries and not self.may_wait(fault, trouble):
            return self.failure(fault, trouble, retries - 1)
        return None

    def after_failed_recovery(self, again: hal.DeviceFault, previous: hal.DeviceFault,
                              retries: int, trouble: Trouble, announced: bool
                              ) -> AfterRecovery:
        """What follows a recovery that raised ``again`` (``retries`` counts it), the
        suspension having begun with (or last seen) ``previous``."""
        if not again.recoverable:
            return AfterRecovery(self._unrecoverable(again, trouble), None, announced)
        if retries <= self.policy.max_retries:
            return AfterRecovery(None, {"device": again.device, "code": again.code,
                                        "message": str(again), "retry": retries}, announced)
        if not self.may_wait(again, trouble):
            return AfterRecovery(self.failure(again, trouble, retries - 1), None, announced)
        if announced and str(again) == str(previous):
            return AfterRecovery(None, None, announced)
        # One event when the waiting starts (and when the cause changes), not one per probe:
        # a lab may leave a job waiting for many minutes.
        left = max(self.policy.wait_for_device_s - (self._clock() - trouble.since), 0.0)
        # A port that cannot be opened (code "port": a serial adapter unplugged) is not a
        # device that is silent: its message says which port; the note says what to do.
        gone, check = (("has no port to talk through", "plug its USB adapter or cable back in")
                       if again.code == "port" else
                       ("does not answer", "check its power and cable"))
        return AfterRecovery(None, {
            "device": again.device, "code": again.code, "message": str(again),
            "retry": retries, "waiting_s": round(left, 1),
            "note": f"{again.device} {gone}; waiting up to {left:.0f} s more for it "
                    f"({check}); the job resumes from its checkpoint when it answers"}, True)

    def may_wait(self, fault: hal.DeviceFault, trouble: Trouble) -> bool:
        """True while a silent device may still be waited for (``wait_for_device_s``)."""
        limit = self.policy.wait_for_device_s
        return (isinstance(fault, hal.DeviceUnavailable) and limit > 0
                and self._clock() - trouble.since < limit)

    def failure(self, fault: hal.DeviceFault, trouble: Trouble, retries: int) -> str:
        """The reason of a job failed by a fault that persisted after ``retries`` retries."""
        waited = self._clock() - trouble.since
        limit = self.policy.wait_for_device_s
        how = f"{retries} retries"
        if isinstance(fault, hal.DeviceUnavailable) and limit > 0:
            how += f" and {waited:.0f} s (wait_for_device_s {limit:g})"
        return (f"device fault persisted after {how}: {fault} (code {fault.code})"
                + trouble.began_as(fault) + "; fix the device and submit the job again")

    @staticmethod
    def _unrecoverable(fault: hal.DeviceFault, trouble: Trouble) -> str:
        return f"unrecoverable device fault: {fault}" + trouble.began_as(fault)
