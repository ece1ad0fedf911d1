"""Child process: ``gonio serve ARGS`` whose job worker raises on its first job.

Stands in for any bug that kills the worker (the two-daemons ``IntegrityError`` of issue 10
was one): the daemon must then fail ``/health`` and exit non-zero so systemd restarts it.
"""

from __future__ import annotations

import sys
from typing import Any

from gonio.cli import main
from gonio.worker import Worker


async def _die(self: Worker, job: Any) -> Any:
    raise RuntimeError(f"injected worker failure at job {job.id}")


Worker.run_job = _die  # type: ignore[method-assign]

if __name__ == "__main__":
    raise SystemExit(main(["serve", *sys.argv[1:]]))
