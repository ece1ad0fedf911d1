"""A plan's fault policy applied (gonio.plans.faults): when a fault suspends, when it fails.

The expected decisions are the policy's documented rule (gonio.plans.models.FaultPolicy):
more than ``max_retries`` consecutive failures fail the job, a silent device is waited for
up to ``wait_for_device_s`` from the first fault, an unrecoverable fault fails at once.
"""

from __future__ import annotations

from gonio import hal
from gonio.plans.faults import Suspender
from gonio.plans.models import FaultPolicy


class Clock:
    """Monotonic seconds that a test sets."""

    def __init__(self) -> None:
        self.now = 1000.0

    def __call__(self) -> float:
        return self.now


def test_retries_then_failure_naming_the_first_cause() -> None:
    clock = Clock()
    rules = Suspender(FaultPolicy(max_retries=2, wait_for_device_s=0.0), clock)
    first = hal.StageFault("stage", "overload", code="overload")
    trouble = rules.trouble(first)
    assert rules.refusal(first, 1, trouble) is None
    assert rules.refusal(first, 2, trouble) is None
    later = hal.StageFault("stage", "overheating", code="temp")
    why = rules.refusal(later, 3, trouble)
    assert why is not None
    assert why.startswith("device fault persisted after 2 retries: stage: overheating")
    assert "it began as: stage: overload (code overload)" in why


def test_an_unrecoverable_fault_fails_at_once() -> None:
    rules = Suspender(FaultPolicy(max_retries=5))
    fault = hal.DeviceFault("lamp", "burnt out", recoverable=False)
    why = rules.refusal(fault, 1, rules.trouble(fault))
    assert why == "unrecoverable device fault: lamp: burnt out"


def test_a_silent_device_is_waited_for_then_given_up() -> None:
    """Past its retries a device that does not answer is waited for; one event says so
    (with the seconds left), repeats say nothing, and after wait_for_device_s it fails."""
    clock = Clock()
    rules = Suspender(FaultPolicy(max_retries=1, wait_for_device_s=60.0), clock)
    silent = hal.DeviceUnavailable("sensor", "no reply", code="timeout")
    trouble = rules.trouble(silent)
    within = rules.after_failed_recovery(silent, silent, 1, trouble, announced=False)
    assert within.failure is None and within.event is not None
    assert "waiting_s" not in within.event and within.event["retry"] == 1
    clock.now += 20.0
    first_wait = rules.after_failed_recovery(silent, silent, 2, trouble, announced=False)
    assert first_wait.failure is None and first_wait.announced
    assert first_wait.event is not None and first_wait.event["waiting_s"] == 40.0
    again = rules.after_failed_recovery(silent, silent, 3, trouble, announced=True)
    assert again == type(again)(None, None, True)
    assert rules.refusal(silent, 4, trouble) is None  # still within the minute
    clock.now += 41.0
    late = rules.after_failed_recovery(silent, silent, 5, trouble, announced=True)
    assert late.failure is not None
    assert "4 retries and 61 s (wait_for_device_s 60)" in late.failure


def test_a_vanished_port_is_waited_for_saying_to_plug_it_back() -> None:
    """A serial port that disappeared (code "port") is not "a device that does not answer":
    the waiting note says to plug its adapter back in, and the message (the driver's) says
    which port, once."""
    clock = Clock()
    rules = Suspender(FaultPolicy(max_retries=0, wait_for_device_s=60.0), clock)
    gone = hal.DeviceUnavailable(
        "stage", "serial port '/dev/ttyUSB0' does not exist (nothing is plugged in under that "
        "name); check the USB adapter and the port name in the rig config", code="port")
    then = rules.after_failed_recovery(gone, gone, 1, rules.trouble(gone), announced=False)
    assert then.failure is None and then.event is not None
    note = then.event["note"]
    assert note.startswith("stage has no port to talk through; waiting up to 60 s"), note
    assert "plug its USB adapter or cable back in" in note and "does not answer" not in note
    assert then.event["message"].count("/dev/ttyUSB0") == 1


def test_a_fault_that_answers_is_not_waited_for() -> None:
    rules = Suspender(FaultPolicy(max_retries=0, wait_for_device_s=600.0), Clock())
    fault = hal.StageFault("stage", "position error", code="pos")
    assert rules.refusal(fault, 1, rules.trouble(fault)) is not None
