"""The service's request and answer models (gonio.service_models): limits, mapping from the
store, and the errors they raise."""

from __future__ import annotations

from pathlib import Path

import pytest
from pydantic import ValidationError

from gonio.jobstates import JobState
from gonio.service_models import (
    Event,
    JobInfo,
    JobRequest,
    NotFound,
    ReorderRequest,
    StageRequest,
    job_row,
)
from gonio.store import JobStore


def test_job_info_copies_the_stored_row(tmp_path: Path) -> None:
    store = JobStore(tmp_path / "jobs.sqlite")
    row = store.create_job(kind="adaptive", specimen="felt", plan={"kind": "adaptive"}, rig={},
                           priority=3)
    info = JobInfo.from_row(row)
    assert (info.id, info.state, info.kind, info.specimen, info.priority) == (
        row.id, JobState.QUEUED, "adaptive", "felt", 3)
    assert info.max_angles is None and info.started is None
    assert JobInfo.from_row(row, max_angles=12).max_angles == 12
    (ev,) = store.events_after(0)
    assert Event.from_row(ev).model_dump() == {"seq": ev.seq, "type": "created",
                                               "job_id": row.id, "time": ev.time,
                                               "data": ev.data}


def test_unknown_jobs_are_not_found_by_id(tmp_path: Path) -> None:
    store = JobStore(tmp_path / "jobs.sqlite")
    with pytest.raises(NotFound, match="no job with id 41"):
        job_row(store, 41)


@pytest.mark.parametrize("priority", [-1001, 1001])
def test_priorities_outside_the_documented_range_are_refused(priority: int) -> None:
    # docs/api.md: priority -1000..1000, higher runs first.
    with pytest.raises(ValidationError, match="priority"):
        JobRequest.model_validate({"plan": {"kind": "uniform"}, "priority": priority})
    with pytest.raises(ValidationError, match="priority"):
        ReorderRequest(priority=priority)


def test_queue_positions_start_at_zero() -> None:
    assert ReorderRequest(position=0).position == 0
    with pytest.raises(ValidationError, match="position"):
        ReorderRequest(position=-1)


def test_stage_requests_name_their_action() -> None:
    assert StageRequest(action="move", angle_deg=30.0).angle_deg == 30.0
    with pytest.raises(ValidationError, match="action"):
        StageRequest.model_validate({"action": "spin"})
    with pytest.raises(ValidationError):
        StageRequest(action="move", angle_deg=float("nan"))  # finite numbers only
