"""Fault injection for the simulated rotation stages (Dynamixel and Zaber).

One :class:`FaultPlan` is shared by a stage simulator's protocol adapter (wire faults: corrupted
or dropped replies, a silent device) and its device model (mechanical faults: stall, overload).
Tests arm faults at run time from their own thread while the simulator's reader thread consumes
them, so every access goes through one lock.

Counters (``corrupt_replies``, ``drop_replies``) count down: each reply that is corrupted or
dropped uses one. Flags (``silent``) stay until cleared. Mechanical faults (``stall_next_move``,
``overload_next_move``) are consumed by the next move the device starts.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass, field, fields

# Here rather than beside the parser in rig.py (SimRig.apply_fault): ``gonio sim --help`` shows it,
# and this module loads in no time where rig.py loads the whole simulated rig.
FAULT_HELP = (
    "silence:NAME[:SECONDS] (a lamp or sensor stops answering), lamp-drift:NAME:FACTOR "
    "(a lamp's output is scaled by FACTOR), saturate:NAME (a sensor reads full scale), "
    "stage-silent, stage-overload, stage-stall, stage-power-cycle[:SECONDS] (the Dynamixel "
    "off for SECONDS, 1 by default, then powered up: a geared one forgets whole motor turns)"
)
"""The faults a simulated rig injects from text (``gonio sim --fault``, ``SimRig.apply_fault``)."""


@dataclass
class FaultPlan:
    """Faults to inject into a simulated stage; thread-safe to arm and consume.

    Parameters
    ----------
    corrupt_replies : int
        Number of next replies to corrupt (Dynamixel: wrong CRC; Zaber: garbled line).
    drop_replies : int
        Number of next replies to drop (the command is still executed).
    silent : bool
        The device ignores everything (as if unplugged or at another baud rate) until cleared.
    stall_next_move : bool
        The next move stops short of its target (mechanical blockage).
    stall_fraction : float
        Fraction of the stalled move's distance travelled before it stops, in [0, 1).
    overload_next_move : bool
        The next move trips an overload part-way (Dynamixel: Hardware Error Status bit 5 and
        torque off; Zaber: driver disabled, ``FD``).
    """

    corrupt_replies: int = 0
    drop_replies: int = 0
    silent: bool = False
    stall_next_move: bool = False
    stall_fraction: float = 0.5
    overload_next_move: bool = False
    _lock: threading.Lock = field(default_factory=threading.Lock, repr=False, compare=False)

    def set(self, **changes: object) -> None:
        """Arm faults at run time, e.g. ``plan.set(drop_replies=2)``.

        Raises
        ------
        ValueError
            For a name that is not a fault of this plan.
        """
        names = {f.name for f in fields(self) if not f.name.startswith("_")}
        unknown = sorted(set(changes) - names)
        if unknown:
            raise ValueError(f"unknown stage fault(s) {unknown}; known: {sorted(names)}")
        with self._lock:
            for name, value in changes.items():
                setattr(self, name, value)

    def clear(self) -> None:
        """Disarm every fault."""
        with self._lock:
            self.corrupt_replies = 0
            self.drop_replies = 0
            self.silent = False
            self.stall_next_move = False
            self.overload_next_move = False

    def is_silent(self) -> bool:
        with self._lock:
            return self.silent

    def take_drop(self) -> bool:
        """True (and one count used) when the next reply must be dropped."""
        with self._lock:
            if self.drop_replies > 0:
                self.drop_replies -= 1
                return True
            return False

    def take_corrupt(self) -> bool:
        """True (and one count used) when the next reply must be corrupted."""
        with self._lock:
            if self.corrupt_replies > 0:
                self.corrupt_replies -= 1
                return True
            return False

    def take_stall(self) -> float | None:
        """Fraction of travel before a stall when the starting move must stall, else None."""
        with self._lock:
            if self.stall_next_move:
                self.stall_next_move = False
                return min(max(self.stall_fraction, 0.0), 0.99)
            return None

    def take_overload(self) -> bool:
        """True when the starting move must trip an overload."""
        with self._lock:
            if self.overload_next_move:
                self.overload_next_move = False
                return True
            return False
