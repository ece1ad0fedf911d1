"""Result files as the service serves them (gonio.result_views): every way a result can be
missing or damaged is said with the job and the command that rebuilds it."""

from __future__ import annotations

from pathlib import Path

import pytest

from gonio.export import ExportError
from gonio.jobstates import JobState
from gonio.result_views import ResultViews
from gonio.results import ResultFileError
from gonio.service_models import NotFound
from gonio.store import JobStore


def _completed(store: JobStore, result_path: str | None, summary: dict[str, object]) -> int:
    job = store.create_job(kind="uniform", specimen="s", plan={}, rig={})
    for state in (JobState.RUNNING, JobState.RECONSTRUCTING, JobState.COMPLETED):
        store.set_state(job.id, state.value)
    store.set_result(job.id, result_path, summary)
    return job.id


@pytest.fixture
def views(tmp_path: Path) -> ResultViews:
    (tmp_path / "data").mkdir()
    return ResultViews(JobStore(tmp_path / "jobs.sqlite"), tmp_path / "data")


def test_jobs_without_a_result_say_what_state_they_are_in(views: ResultViews) -> None:
    with pytest.raises(NotFound, match="no job with id 7"):
        views.result_path(7)
    queued = views.store.create_job(kind="uniform", specimen="s", plan={}, rig={})
    with pytest.raises(NotFound, match=f"job {queued.id} has no result yet \\(it is queued\\)"):
        views.result(queued.id)
    with pytest.raises(NotFound, match="no result yet"):
        views.metrics(queued.id)


def test_result_paths_are_relative_to_the_data_directory(views: ResultViews) -> None:
    job = _completed(views.store, "results/job-1.h5", {})
    assert views.result_path(job) == views.data_dir / "results" / "job-1.h5"


def test_a_missing_result_file_names_the_rebuild_command(views: ResultViews) -> None:
    job = _completed(views.store, "results/gone.h5", {})
    with pytest.raises(NotFound, match=f"gone.h5 is missing.*gonio jobs rebuild {job} --db"):
        views.result(job)


def test_a_damaged_result_file_is_never_served(views: ResultViews) -> None:
    job = _completed(views.store, "bad.h5", {})
    (views.data_dir / "bad.h5").write_bytes(b"not an HDF5 file at all")
    with pytest.raises(ResultFileError, match=f"job {job}'s result file is damaged.*rebuild"):
        views.checked_result_path(job)
    (line,) = views.damaged_results()
    assert line.startswith(f"job {job}: ") and f"gonio jobs rebuild {job}" in line


def test_metrics_add_the_headline_error_with_its_meaning(views: ResultViews) -> None:
    job = _completed(views.store, "r.h5", {"predicted_log_rmse": 0.02, "n_pairs": 12})
    m = views.metrics(job)
    assert m["n_pairs"] == 12 and m["predicted_log_rmse"] == 0.02
    assert "0.020" in str(m["headline_error"])


def test_a_mesh_is_asked_of_gltf_only_before_any_file_is_touched(views: ResultViews) -> None:
    job = _completed(views.store, "r.h5", {})
    with pytest.raises(ExportError, match="gltf only"):
        views.export(job, "mtlx", with_mesh=True)
    with pytest.raises(ExportError, match="unknown export format 'obj'"):
        views.export(job, "obj")
    assert not (views.data_dir / "exports").exists()
