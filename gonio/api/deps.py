"""Shared FastAPI dependencies: the service, path parameters, and the guard sets of routes."""

from __future__ import annotations

from typing import Annotated

from fastapi import Depends, Path, Request

from gonio.api.auth import require_key_when_configured, require_read_access, require_write_key
from gonio.api.maintenance import refuse_while_locked
from gonio.service import GonioService


async def get_service(request: Request) -> GonioService:
    # async on purpose: FastAPI runs a plain ``def`` dependency in its thread pool, so every
    # request (the status poll included) paid a thread hop, and under load dozens of pool
    # threads queued for the interpreter lock in front of the engine's thread.
    service: GonioService = request.app.state.service
    return service


Service = Annotated[GonioService, Depends(get_service)]

# Job ids are positive integers: anything else (a path, "../x", a huge number) is a 422 before
# any handler runs, which is what makes "result by job id only" traversal-proof.
MAX_ID = 2**62
"""Largest job id or event seq a request may name (SQLite integers are 64-bit signed)."""

JobId = Annotated[int, Path(ge=1, le=MAX_ID, description="job id, as returned when it was created")]

READ = [Depends(require_read_access)]
"""Read-only routes: open, or keyed when the daemon is configured so."""

COMPUTE = [Depends(require_key_when_configured)]
"""Reads that compute (dry run): keyed whenever the daemon has keys; not blocked by the lock."""

WRITE = [Depends(require_write_key), Depends(refuse_while_locked)]
"""Mutating routes: a valid key, and no maintenance lock (checked in that order: 401/403, 423)."""
