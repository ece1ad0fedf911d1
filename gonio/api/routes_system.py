"""Health, Prometheus metrics and the live event stream."""

from __future__ import annotations

import time
from collections import Counter
from typing import Any

from fastapi import APIRouter, Header, Query, Request
from fastapi.responses import JSONResponse, PlainTextResponse, StreamingResponse
from pydantic import BaseModel, Field

from gonio import __version__
from gonio.api.deps import MAX_ID, READ, Service
from gonio.api.events import sse_stream
from gonio.api.prometheus import CONTENT_TYPE, Sample, render
from gonio.jobstates import JobState

router = APIRouter(tags=["system"])


class Health(BaseModel):
    status: str
    version: str
    seq: int
    uptime_s: float
    error: str | None = None
    disk_full: str | None = Field(
        default=None, description="why no job starts: the data directory's disk is full "
        "(status 'disk_full'); jobs run again once it has room")


@router.get("/health", summary="Liveness: the daemon answers, its store is readable and its job "
                               "worker runs (503 when the worker died; status 'disk_full' while "
                               "the data directory's disk is full)",
            response_model=Health,
            responses={503: {"model": Health, "description": "the job worker died; the daemon "
                             "is stopping so its supervisor can restart it"}})
async def health(service: Service, request: Request) -> Any:
    out = Health(
        status="ok",
        version=__version__,
        seq=service.seq,
        uptime_s=time.monotonic() - request.app.state.started_at,
    )
    if service.worker_failure is not None:
        failed = out.model_copy(update={"status": "failed",
                                        "error": f"job worker died: {service.worker_failure}"})
        return JSONResponse(failed.model_dump(), status_code=503)
    full = service.disk_full
    if full is not None:
        # 200: the daemon is alive and answers; a restart would not free any space.
        return out.model_copy(update={"status": "disk_full", "disk_full": full, "error": full})
    return out


@router.get(
    "/metrics",
    dependencies=READ,
    response_class=PlainTextResponse,
    responses={200: {"content": {CONTENT_TYPE: {}}}},
    summary="Prometheus metrics (text exposition format 0.0.4)",
)
def metrics(service: Service, request: Request) -> PlainTextResponse:
    counts = Counter(j.state for j in service.list_jobs())
    samples = [
        Sample("gonio_jobs", "Jobs in the store, by state.", counts.get(s, 0), {"state": s.value})
        for s in JobState
    ]
    samples.append(Sample("gonio_events_seq", "Sequence number of the latest event.", service.seq))
    samples.append(Sample("gonio_sse_subscribers", "Open event streams.",
                          request.app.state.sse_subscribers))
    samples.append(Sample("gonio_maintenance_locked", "1 while the maintenance lock is set.",
                          float(request.app.state.maintenance.state().locked)))
    st = service.status()
    samples.append(Sample("gonio_queue_held",
                          "1 while the queue is held (halt, failure, maintenance lock).",
                          float(st.queue_held is not None)))
    if st.running is not None:
        labels = {"job": str(st.running.id)}
        samples.append(Sample("gonio_job_angles_done", "Stage angles measured in the running job.",
                              float(st.running.done_angles), labels))
        samples.append(Sample("gonio_job_angles_total", "Stage angles planned in the running job.",
                              float(st.running.total_angles), labels))
    return PlainTextResponse(render(samples, request.app.state.request_stats),
                             media_type=CONTENT_TYPE)


@router.get(
    "/api/v1/events",
    dependencies=READ,
    response_class=StreamingResponse,
    responses={200: {"content": {"text/event-stream": {}}},
               404: {"description": "job_id names no job (never submitted, or removed)"}},
    summary="Live events (server-sent events); resume with Last-Event-ID or ?since=",
)
async def events(
    service: Service,
    request: Request,
    since: int | None = Query(None, ge=0, le=MAX_ID, description="replay events after this seq"),
    job_id: int | None = Query(None, ge=1, le=MAX_ID, description="only this job's events"),
    last_event_id: str | None = Header(None, description="set by EventSource on reconnect"),
) -> StreamingResponse:
    if job_id is not None:
        # A job that does not exist would give a stream that never says anything: a typo'd
        # id would look like a quiet job. NotFound -> 404, as every other job route.
        service.get_job(job_id)
    start = since
    if start is None and last_event_id is not None:
        text = last_event_id.strip()
        # Anything but a plain seq (garbage, or larger than SQLite's integers) means "now".
        if text.isascii() and text.isdigit() and len(text) < 19:
            start = int(text)
    if start is None:
        start = service.seq  # a fresh client wants what happens from now on
    app_state = request.app.state

    async def counted():  # type: ignore[no-untyped-def]
        app_state.sse_subscribers += 1
        try:
            async for chunk in sse_stream(service.subscribe(start, job_id=job_id),
                                          app_state.sse_heartbeat_s,
                                          app_state.stream_closer.event()):
                yield chunk
        finally:
            app_state.sse_subscribers -= 1

    return StreamingResponse(
        counted(),
        media_type="text/event-stream",
        # no-transform / X-Accel-Buffering: proxies must not buffer or compress the stream.
        headers={"Cache-Control": "no-cache, no-transform", "X-Accel-Buffering": "no"},
    )
