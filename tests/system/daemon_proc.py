"""Run ``gonio`` commands and daemons as separate processes, as a lab would.

Ownership (data-directory and rig locks) is per process, so the tests of who owns what need real
child processes: a daemon here and a CLI there, each with its own pid.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import httpx

PROJECT_ROOT = Path(__file__).resolve().parents[2]
TEST_KEY = "ownership-test-key-0123456789"
SERVING = re.compile(r"gonio serving on (http://\S+)")
# The installed console script beside this interpreter: children show up as "gonio serve ...".
GONIO = [str(Path(sys.executable).with_name("gonio"))]


def child_env(**extra: str) -> dict[str, str]:
    """The environment of a child gonio: this interpreter's packages, a known API key."""
    env = {**os.environ, "PYTHONPATH": str(PROJECT_ROOT), "GONIO_API_KEYS": f"t:{TEST_KEY}"}
    env.update(extra)
    return env


def gonio(args: Sequence[str], timeout: float = 120.0, cwd: Path | None = None, **env: str
          ) -> subprocess.CompletedProcess[str]:
    """Run ``gonio ARGS`` to its end in a child process, in ``cwd`` (default: the project
    root)."""
    return subprocess.run([*GONIO, *args], capture_output=True, text=True, timeout=timeout,
                          env=child_env(**env), cwd=cwd or PROJECT_ROOT)


@dataclass
class DaemonProcess:
    """A ``gonio serve`` child; :attr:`url` once it listens; stdout/stderr collected."""

    proc: subprocess.Popen[str]
    url: str = ""
    out: list[str] = field(default_factory=list)
    err: list[str] = field(default_factory=list)

    @property
    def pid(self) -> int:
        return self.proc.pid

    def client(self) -> httpx.Client:
        return httpx.Client(base_url=self.url, headers={"X-API-Key": TEST_KEY}, timeout=30)

    def stop(self, sig: int | None = None) -> int:
        """Send ``sig`` (default SIGTERM), wait for the exit and return its status."""
        if self.proc.poll() is None:
            if sig is None:
                self.proc.terminate()
            else:
                self.proc.send_signal(sig)
        try:
            return self.proc.wait(timeout=60)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            return self.proc.wait(timeout=10)

    def text(self) -> str:
        return "".join(self.out) + "".join(self.err)


def start_daemon(args: Sequence[str], timeout: float = 120.0,
                 command: Sequence[str] | None = None, cwd: Path | None = None,
                 **env: str) -> DaemonProcess:
    """Start ``gonio serve ARGS`` (or ``COMMAND ARGS``) and wait until it prints its address;
    in ``cwd`` (default: the project root).

    Raises
    ------
    RuntimeError
        It exited (or did not listen within ``timeout``); the message has its output.
    """
    proc = subprocess.Popen([*(command or [*GONIO, "serve"]), *args],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=child_env(**env), cwd=cwd or PROJECT_ROOT)
    d = DaemonProcess(proc)
    ready = threading.Event()

    def pump(stream: object, sink: list[str], watch: bool) -> None:
        for line in stream:  # type: ignore[attr-defined]
            sink.append(line)
            m = SERVING.search(line) if watch else None
            if m and not d.url:
                d.url = m.group(1).rstrip("/")
                ready.set()
        ready.set()  # the stream ended: the process is gone

    threading.Thread(target=pump, args=(proc.stdout, d.out, True), daemon=True).start()
    threading.Thread(target=pump, args=(proc.stderr, d.err, False), daemon=True).start()
    deadline = time.monotonic() + timeout
    while not d.url and time.monotonic() < deadline and proc.poll() is None:
        ready.wait(0.2)
    if not d.url:
        d.stop()
        raise RuntimeError(f"gonio serve {' '.join(args)} did not start:\n{d.text()}")
    return d


def wait_for(predicate: object, timeout: float = 120.0, what: str = "condition") -> None:
    """Poll ``predicate()`` until true; ``TimeoutError`` naming ``what`` otherwise."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():  # type: ignore[operator]
            return
        time.sleep(0.1)
    raise TimeoutError(f"timed out after {timeout:g} s waiting for {what}")
