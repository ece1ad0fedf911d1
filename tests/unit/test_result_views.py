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


def test_a_job_that_ended_without_a_result_is_not_said_to_have_none_yet(
    views: ResultViews,
) -> None:
    """GET /jobs/3/export of an aborted job said "job 3 has no result yet (it is aborted)":
    "yet" promises one. A finished job without a result says how it ended, and why."""
    for state, reason in ((JobState.ABORTED, None), (JobState.FAILED, "stage fault: E12")):
        job = views.store.create_job(kind="uniform", specimen="s", plan={}, rig={})
        views.store.set_state(job.id, state.value, reason=reason)
        for ask in (views.result, views.metrics):
            with pytest.raises(NotFound) as info:
                ask(job.id)
            said = str(info.value)
            assert "yet" not in said and f"job {job.id} ended {state.value}" in said, said
            assert reason is None or reason in said, said
    with pytest.raises(NotFound, match="ended aborted"):  # what the export route says
        views.export(job.id - 1, "gltf")


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
    with pytest.raises(ExportError, match="gltf or glb only"):
        views.export(job, "mtlx", with_mesh=True)
    with pytest.raises(ExportError, match="unknown export format 'obj'"):
        views.export(job, "obj")
    assert not (views.data_dir / "exports").exists()


def test_a_spectral_results_preview_shows_its_colour_not_its_first_three_bands(
        views: ResultViews) -> None:
    """A red paint read by 31-band spectrometers (400-700 nm) was previewed as its first
    three bands (400, 410, 420 nm) taken for R, G and B: grey, where the page's rendering of
    the same result, in linear sRGB from XYZ, is red. The preview now shows the same linear
    sRGB as the renderings (gonio.result_colour.linear_srgb)."""
    import io

    import numpy as np
    from PIL import Image

    from gonio.brdf.colour.spectral import SpectralBands
    from gonio.brdf.tables.table import BRDFTable, from_function
    from gonio.calibration import CalibratedScan
    from gonio.results import write_result

    wl = tuple(float(w) for w in range(400, 701, 10))
    # A red diffuser: reflects 60 % above 600 nm, 4 % below (albedo / pi in 1/sr).
    red = np.where(np.asarray(wl) >= 600.0, 0.60, 0.04) / np.pi
    t = from_function(lambda i, o: np.tile(red, (i.shape[0], 1)),
                      [f"{w:.0f}nm" for w in wl], "red paint", dtype=np.float32)
    table = BRDFTable.trusted(np.asarray(t.values), t.channels, "red paint", wl)
    scan = CalibratedScan(
        pairs=[("L1", "S1")], light_dirs=np.array([[0.0, 0.0, 1.0]]),
        sensor_dirs=np.array([[0.0, 0.0, 1.0]]), stage_angles_deg=np.zeros(1),
        values=np.ones((1, 1, len(wl))), channels=table.channels,
        calibration={"pairs": [{"light": "L1", "sensor": "S1", "factor": [1.0] * len(wl)}]})
    write_result(views.data_dir / "red.h5", job_id=1, specimen="red paint", kind="uniform",
                 readings=[], samples=scan, table=table,
                 colour={"bands": SpectralBands(wl, (10.0,) * len(wl)).as_dict()})
    job = _completed(views.store, "red.h5", {})

    png = Image.open(io.BytesIO(views.preview_png(job))).convert("RGB")
    pixels = np.asarray(png, dtype=float)
    # The panels' valid cells (and the colour bar, at the table's typical tint) are red: R
    # above G and B (each channel on the preview's log scale, so a pale red). The bands
    # 400-420 nm, equal here, drew every cell white.
    red_pixels = pixels[..., 0] >= pixels[..., 1:].max(axis=-1) + 25
    assert red_pixels.mean() > 0.2, red_pixels.mean()


def test_download_names_carry_the_job_and_its_specimen_made_safe() -> None:
    from gonio.result_views import download_stem

    assert download_stem(7, "brushed steel") == "gonio-job-7-brushed-steel"
    assert download_stem(7, "Stoff grün / Probe 3") == "gonio-job-7-Stoff-grun-Probe-3"
    assert download_stem(7, "../../etc/passwd") == "gonio-job-7-etc-passwd"
    assert download_stem(7, "a\\b:c*?\"<>|") == "gonio-job-7-a-b-c"
    assert download_stem(7, "  ") == download_stem(7, "///") == "gonio-job-7"
    assert download_stem(7, "日本") == "gonio-job-7"
    assert len(download_stem(7, "x" * 500)) == len("gonio-job-7-") + 60
