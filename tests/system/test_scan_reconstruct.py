"""Whole jobs through the service on the simulated rig: measure, reconstruct, write the result."""

from __future__ import annotations

import asyncio
from pathlib import Path

import numpy as np
import pytest

from gonio.calibration import Calibration, PairCalibration
from gonio.drivers.factory import build_rig
from gonio.jobstates import JobState
from gonio.plans.models import AdaptivePlan, ExposureSettings, UniformPlan
from gonio.results import read_result
from gonio.service import GonioService, JobRequest
from gonio.sim.rig import SimRig, SimRigOptions, start_sim_rig
from gonio.store import JobStore

pytestmark = [pytest.mark.system, pytest.mark.slow]
FAST = ExposureSettings(exposure_s=0.02, light_settle_s=0.0, dark="once")


def _write_true_calibration(sim: SimRig, data_dir: Path) -> None:
    pairs = [
        PairCalibration(light=p.light, sensor=p.sensor, factor=(
            1.0 / sim.expected_counts_per_brdf(p.light, p.sensor, FAST.exposure_s),) * 3)
        for p in sim.config.pair_list()
    ]
    data_dir.mkdir(parents=True, exist_ok=True)
    (data_dir / "calibration.json").write_text(Calibration(pairs=tuple(pairs)).model_dump_json())


@pytest.mark.parametrize(("stage", "plan"), [
    ("dynamixel", UniformPlan(rotations=8, exposure=FAST)),
    ("zaber", AdaptivePlan(initial_rotations=8, threshold=0.1, max_rounds=2, exposure=FAST)),
])
def test_job_reconstructs_the_simulated_specimen(
    tmp_path: Path, stage: str, plan: UniformPlan | AdaptivePlan
) -> None:
    with start_sim_rig(SimRigOptions(stage=stage, time_scale=10.0, seed=11)) as sim:
        _write_true_calibration(sim, tmp_path / "data")
        svc = GonioService(JobStore(tmp_path / "jobs.sqlite"), build_rig(sim.config),
                           rig_config=sim.config, data_dir=tmp_path / "data")
        # Nothing here looks at the export fits (about 7 s of CPU per scan; asserted by
        # tests/system/api/test_scan_flow.py's full scan): the scan finishes without them.
        svc.worker.fit_exports = False

        async def go() -> None:
            await svc.start()
            info = svc.submit(JobRequest(plan=plan))
            async for ev in svc.subscribe(0, job_id=info.id):
                if ev.type == "state" and ev.data["state"] in ("completed", "failed", "aborted"):
                    break
            await svc.stop()

        asyncio.run(go())
        job = svc.get_job(1)
        assert job.state is JobState.COMPLETED, job.reason
        res = read_result(svc.result_path(1))
        assert res.table is not None
        # The reconstruction reproduces its own samples within 25 % on average (V&F report
        # comparable sample errors for r = 8 with a synthetic basis), and the self-estimate is
        # 0.8 of that.
        assert res.rel_sample_error is not None and res.rel_sample_error < 0.25
        assert res.estimated_error == pytest.approx(0.8 * res.rel_sample_error)
        # Evaluated at the measured geometry the table follows the specimen's true BRDF.
        s = res.samples
        truth = np.stack([[sim.true_brdf(a, b, ang) for ang in s.stage_angles_deg]
                          for a, b in s.pairs])
        np.testing.assert_allclose(s.values, truth, rtol=0.1, atol=0.02 * truth.max())
        from gonio.brdf.tables.geometry import lab_to_specimen

        wi = lab_to_specimen(s.light_dirs[:, None, :], np.deg2rad(s.stage_angles_deg)[None, :])
        wo = lab_to_specimen(s.sensor_dirs[:, None, :], np.deg2rad(s.stage_angles_deg)[None, :])
        fit = res.table.eval(wi, wo)
        rel = np.abs(fit - truth) / np.maximum(truth, 0.05 * truth.max())
        assert float(np.median(rel)) < 0.3
        assert svc.preview_png(1).startswith(b"\x89PNG")
        assert job.result is not None
        assert job.result["n_samples"] == s.values.shape[0] * s.values.shape[1]
        # The reported error bar is the calibrated cross-validated one, stored with the result.
        predicted = res.metrics["predicted_error"]
        assert np.isfinite(predicted) and predicted > res.estimated_error
        assert job.result["predicted_error"] == pytest.approx(predicted)
        # The headline self-estimate (expected log_rmse) is in the file and the job's JSON.
        plr = res.metrics["predicted_log_rmse"]
        assert np.isfinite(plr) and plr > 0
        assert job.result["predicted_log_rmse"] == pytest.approx(plr)
