"""Simulated Zaber rotary stage speaking the Zaber ASCII protocol, on a pty or on TCP.

Layers: :class:`ZaberRotaryAxis` is the device (position counter, homing, warning flags,
speed and acceleration settings, motion through :class:`~gonio.sim.motion.StageMotion`);
:class:`ZaberAsciiAdapter` parses command lines and formats replies (and injects wire faults);
a transport carries the lines: :class:`~gonio.sim.pty.PtyTransport` or :class:`TcpLineServer`.

Protocol subset (Zaber ASCII protocol manual): commands ``/<device> [<axis> [<id>]] <command>``
ending in CR or LF; replies ``@<dd> <axis> [<id>] <OK|RJ> <BUSY|IDLE> <flag|--> <data>`` ending
in CRLF. Commands: empty (status poll), ``home``, ``move abs|rel N``, ``stop``, ``estop``,
``get pos|maxspeed|accel|limit.min|limit.max``, ``set maxspeed|accel N``, ``warnings``,
``warnings clear``.

Settings units (Zaber convention): ``maxspeed`` = microsteps/s x 1.6384 and ``accel`` =
microsteps/s^2 x 1.6384 / 10000.

Choices of this simulator where the manual leaves room: a move while the axis has no reference
position is rejected with ``BADCOMMAND`` and flag ``WR``; a stall latches ``FS``, an overload
latches ``FD`` (the driver is disabled and moves do nothing) until ``warnings clear``. The
optional ``:CC`` message checksum is not supported (such a command is rejected ``BADDATA``).
"""

from __future__ import annotations

import contextlib
import math
import socket
import threading
from collections.abc import Callable

from gonio.sim.faults import FaultPlan
from gonio.sim.motion import StageMotion
from gonio.sim.pty import PtyTransport

SPEED_FACTOR = 1.6384  # maxspeed data units per (microstep/s)
ACCEL_FACTOR = 1.6384 / 10_000  # accel data units per (microstep/s^2)
# Zaber X-RSW60A rotary stage: 0.000234375 degrees per microstep.
DEFAULT_MICROSTEPS_PER_DEGREE = 1.0 / 0.000234375

# Warning flags, highest priority first (Zaber ASCII protocol manual).
FLAG_PRIORITY = (
    "FD", "FQ", "FS", "FT", "FB", "FP", "FE", "WH", "WL", "WP", "WV", "WT", "WM", "WR",
    "NC", "NI", "ND", "NU", "NJ",
)


class Rejected(Exception):
    """A command the device answers with ``RJ``; the message is the reason word."""


class ZaberRotaryAxis:
    """One-axis Zaber rotary stage.

    Parameters
    ----------
    motion : StageMotion
        Physics of the stage, degrees. Physical 0 degrees is the home sensor.
    microsteps_per_degree : float
        Microsteps per degree of stage rotation.
    faults : FaultPlan or None
        Mechanical faults (stall, overload) consumed when a move starts.
    """

    def __init__(
        self,
        motion: StageMotion,
        *,
        microsteps_per_degree: float = DEFAULT_MICROSTEPS_PER_DEGREE,
        faults: FaultPlan | None = None,
    ) -> None:
        if not microsteps_per_degree > 0:
            raise ValueError(f"microsteps_per_degree must be > 0, got {microsteps_per_degree}")
        self.motion = motion
        self.faults = faults if faults is not None else FaultPlan()
        self.mpd = float(microsteps_per_degree)
        self._lock = threading.RLock()
        # Until homed, positions count from wherever the stage was at power-up.
        self._offset = round(motion.position_deg() * self.mpd)
        self._homed = False
        self._homing = False
        self._latched: set[str] = set()
        self._stall_latched = False
        self.limit_min = -(2**31 - 1)
        self.limit_max = 2**31 - 1
        self.maxspeed = round(motion.speed_dps * self.mpd * SPEED_FACTOR)
        self.accel = round(motion.accel_dps2 * self.mpd * ACCEL_FACTOR)

    # ------------------------------------------------------------------ state
    def _update(self) -> None:
        if self._homing and not self.motion.is_moving():
            self._homing = False
            if not self.motion.stalled() and not self.motion.overloaded():
                self._homed = True
                self._offset = 0
        if self.motion.stalled() and not self._stall_latched:
            # Latch once per stall: after 'warnings clear' the flag stays off until a new stall.
            self._stall_latched = True
            self._latched.add("FS")
        if self.motion.overloaded():
            self._latched.add("FD")

    def flags(self) -> list[str]:
        """Active warning flags, highest priority first."""
        with self._lock:
            self._update()
            active = set(self._latched)
            if not self._homed:
                active.add("WR")
            return [f for f in FLAG_PRIORITY if f in active]

    def busy(self) -> bool:
        with self._lock:
            return self.motion.is_moving()

    def position(self) -> int:
        """Position counter, microsteps."""
        with self._lock:
            self._update()
            return round(self.motion.position_deg() * self.mpd) - self._offset

    # ------------------------------------------------------------------ commands
    def execute(self, words: list[str]) -> str:
        """Run one command (already split into words); returns the reply data."""
        with self._lock:
            self._update()
            if not words:
                return "0"
            cmd, args = words[0], words[1:]
            if cmd == "home" and not args:
                return self._home()
            if cmd == "move" and len(args) == 2 and args[0] in ("abs", "rel"):
                return self._move(args[0], _int(args[1]))
            if cmd == "stop" and not args:
                self._interrupt(self.motion.stop)
                return "0"
            if cmd == "estop" and not args:
                self._interrupt(self.motion.halt)
                return "0"
            if cmd == "get" and len(args) == 1:
                return self._get(args[0])
            if cmd == "set" and len(args) == 2:
                return self._set(args[0], _int(args[1]))
            if cmd == "warnings" and not args:
                flags = self.flags()
                return " ".join([f"{len(flags):02d}", *flags])
            if cmd == "warnings" and args == ["clear"]:
                flags = self.flags()
                self._latched.clear()
                self.motion.reset_overload()
                return " ".join([f"{len(flags):02d}", *flags])
            raise Rejected("BADCOMMAND")

    def _interrupt(self, how: Callable[[], None]) -> None:
        if self.motion.is_moving():
            self._latched.add("NI")
        self._homing = False
        how()

    def _home(self) -> str:
        self._latched.discard("NI")
        self._homing = True
        self._arm_faults()
        self.motion.move_to(0.0)
        return "0"

    def _move(self, kind: str, value: int) -> str:
        if not self._homed:
            raise Rejected("BADCOMMAND")
        target = value if kind == "abs" else self.position() + value
        if not self.limit_min <= target <= self.limit_max:
            raise Rejected("BADDATA")
        self._latched.discard("NI")
        self._arm_faults()
        self.motion.move_to((target + self._offset) / self.mpd)
        return "0"

    def _arm_faults(self) -> None:
        self._stall_latched = False
        fraction = self.faults.take_stall()
        if fraction is not None:
            self.motion.arm_stall(fraction)
        if self.faults.take_overload():
            self.motion.arm_overload(0.5)

    def _get(self, name: str) -> str:
        values = {
            "pos": self.position(),
            "maxspeed": self.maxspeed,
            "accel": self.accel,
            "limit.min": self.limit_min,
            "limit.max": self.limit_max,
        }
        if name not in values:
            raise Rejected("BADCOMMAND")
        return str(values[name])

    def _set(self, name: str, value: int) -> str:
        if name == "maxspeed":
            if value <= 0:
                raise Rejected("BADDATA")
            self.maxspeed = value
            self.motion.set_speed(value / SPEED_FACTOR / self.mpd)
        elif name == "accel":
            if value < 0:
                raise Rejected("BADDATA")
            self.accel = value
            # 0 means "as fast as the motor can": model it as a near-instant ramp.
            per_s2 = value / ACCEL_FACTOR / self.mpd if value else 1e6
            self.motion.set_accel(per_s2)
        else:
            raise Rejected("BADCOMMAND")
        return "0"


def _int(word: str) -> int:
    try:
        return int(word)
    except ValueError:
        raise Rejected("BADDATA") from None


class ZaberAsciiAdapter:
    """Line protocol front end of a :class:`ZaberRotaryAxis` (one instance per connection)."""

    def __init__(self, axis: ZaberRotaryAxis, device: int, faults: FaultPlan) -> None:
        self.axis = axis
        self.device = device
        self.faults = faults
        self._buf = bytearray()

    def handle(self, data: bytes) -> bytes:
        self._buf += data
        out = bytearray()
        while True:
            cut = [i for i in (self._buf.find(b"\r"), self._buf.find(b"\n")) if i >= 0]
            if not cut:
                return bytes(out)
            line = bytes(self._buf[: min(cut)]).decode("ascii", errors="replace")
            del self._buf[: min(cut) + 1]
            reply = self.reply_to(line)
            if reply is None or self.faults.is_silent() or self.faults.take_drop():
                continue
            if self.faults.take_corrupt():
                reply = reply.replace(" OK ", " 0?\x15 ").replace(" RJ ", " R?\x15 ")
            out += reply.encode("ascii", errors="replace") + b"\r\n"

    def reply_to(self, line: str) -> str | None:
        """The reply line (without CRLF) for one command line, or None when not addressed."""
        line = line.strip()
        if not line.startswith("/"):
            return None  # noise or an empty line between CR and LF
        words = line[1:].split()
        numbers: list[int] = []
        while words and words[0].isdigit() and len(numbers) < 3:
            numbers.append(int(words.pop(0)))
        device = numbers[0] if numbers else 0
        axis = numbers[1] if len(numbers) > 1 else 0
        msg_id = numbers[2] if len(numbers) > 2 else None
        if device not in (0, self.device):
            return None  # another device on the daisy chain
        head = f"@{self.device:02d} {axis}" + (f" {msg_id}" if msg_id is not None else "")
        try:
            if axis not in (0, 1):
                raise Rejected("BADAXIS")
            data = self.axis.execute(words)
            verdict = "OK"
        except Rejected as exc:
            data, verdict = str(exc), "RJ"
        flags = self.axis.flags()
        state = "BUSY" if self.axis.busy() else "IDLE"
        return f"{head} {verdict} {state} {flags[0] if flags else '--'} {data}"


class TcpLineServer:
    """Loopback TCP server feeding each connection to its own adapter (a Zaber X-MCC over IP)."""

    def __init__(self, make_adapter: Callable[[], ZaberAsciiAdapter]) -> None:
        self._make_adapter = make_adapter
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self._sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        self._sock.bind(("127.0.0.1", 0))
        self._sock.listen(4)
        self._sock.settimeout(0.1)
        self.port = self._sock.getsockname()[1]
        self._stop = threading.Event()
        self._conns: list[socket.socket] = []
        self._thread = threading.Thread(target=self._accept, name="zaber-sim-tcp", daemon=True)
        self._thread.start()

    def _accept(self) -> None:
        while not self._stop.is_set():
            try:
                conn, _ = self._sock.accept()
            except TimeoutError:
                continue
            except OSError:
                return
            conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            self._conns.append(conn)
            threading.Thread(target=self._serve, args=(conn,), daemon=True).start()

    def _serve(self, conn: socket.socket) -> None:
        adapter = self._make_adapter()
        conn.settimeout(0.1)
        with conn:
            while not self._stop.is_set():
                try:
                    data = conn.recv(4096)
                except TimeoutError:
                    continue
                except OSError:
                    return
                if not data:
                    return
                reply = adapter.handle(data)
                if reply:
                    try:
                        conn.sendall(reply)
                    except OSError:
                        return

    def close(self) -> None:
        if self._stop.is_set():
            return
        self._stop.set()
        self._thread.join(timeout=2.0)
        for c in [self._sock, *self._conns]:
            with contextlib.suppress(OSError):
                c.close()


class ZaberSimHandle:
    """A running simulated Zaber stage: ``url`` for ``serial.serial_for_url``, ``close()``."""

    def __init__(self, axis: ZaberRotaryAxis, device: int, faults: FaultPlan, transport: str):
        self.axis = axis
        self.motion = axis.motion
        self.faults = faults
        self.device = device
        self._transport: PtyTransport | TcpLineServer
        if transport == "pty":
            self._transport = PtyTransport(self._adapter().handle, name="zaber-sim-pty")
            self.url = self._transport.port
        elif transport == "tcp":
            self._transport = TcpLineServer(self._adapter)
            self.url = f"socket://127.0.0.1:{self._transport.port}"
        else:
            raise ValueError(f"transport must be 'pty' or 'tcp', got {transport!r}")

    def _adapter(self) -> ZaberAsciiAdapter:
        return ZaberAsciiAdapter(self.axis, self.device, self.faults)

    def close(self) -> None:
        self._transport.close()

    def __enter__(self) -> ZaberSimHandle:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def start_zaber_sim(
    motion: StageMotion,
    *,
    transport: str = "pty",
    microsteps_per_degree: float = DEFAULT_MICROSTEPS_PER_DEGREE,
    device: int = 1,
    faults: FaultPlan | None = None,
) -> ZaberSimHandle:
    """Start a simulated Zaber rotary stage.

    Parameters
    ----------
    motion : StageMotion
        Stage physics, degrees.
    transport : {"pty", "tcp"}
        A pseudo-terminal (``url`` is its path) or a loopback TCP port (``url`` is
        ``socket://127.0.0.1:PORT``).
    microsteps_per_degree : float
        Microsteps per degree of stage rotation.
    device : int
        Device number on the chain, 1-99.
    faults : FaultPlan or None
        Shared fault plan; a new empty one when None.
    """
    if not 1 <= device <= 99:
        raise ValueError(f"Zaber device number must be 1-99, got {device}")
    if not math.isfinite(microsteps_per_degree) or microsteps_per_degree <= 0:
        raise ValueError(
            f"microsteps_per_degree must be a positive number, got {microsteps_per_degree}"
        )
    plan = faults if faults is not None else FaultPlan()
    axis = ZaberRotaryAxis(motion, microsteps_per_degree=microsteps_per_degree, faults=plan)
    return ZaberSimHandle(axis, device, plan, transport)
