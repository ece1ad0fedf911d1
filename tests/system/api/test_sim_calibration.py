"""The simulated rig calibrates itself like a real one: white reference, calibration job, 1/sr.

Real drivers against the simulated devices, the real service and worker; the start-up
calibration is the function ``gonio serve --sim`` uses.
"""

from __future__ import annotations

import asyncio
import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from gonio.basis_supply import BasisSupply
from gonio.calibration import Calibration
from gonio.cli.sim_session import start_sim_calibration
from gonio.drivers.factory import build_rig
from gonio.jobstates import JobState
from gonio.plans.models import UniformPlan
from gonio.results import read_result
from gonio.service import GonioService, JobRequest
from gonio.sim.rig import WHITE_REFERENCE_ALBEDO, SimRigOptions, start_sim_rig
from gonio.store import JobStore

pytestmark = pytest.mark.system

TERMINAL = ("completed", "failed", "aborted", "halted")


def test_calibrated_sim_scan_is_in_one_per_sr(tmp_path: Path, basis: Any) -> None:
    data = tmp_path / "data"
    with start_sim_rig(SimRigOptions(time_scale=10.0, settle_s=0.0, seed=5)) as sim:
        specimen = sim.specimen.brdf
        svc = GonioService(JobStore(tmp_path / "jobs.sqlite"), build_rig(sim.config),
                           rig_config=sim.config, basis=BasisSupply(lambda: basis), data_dir=data)
        # Nothing here looks at the export fits (seconds of CPU per scan; asserted by
        # test_scan_flow's full scan): the scan finishes without them.
        svc.worker.fit_exports = False
        reports: list[tuple[int, str]] = []
        placed: dict[str, Any] = {}

        async def go() -> tuple[int, int]:
            await svc.start()
            try:
                def on_progress(ev: Any) -> None:
                    if ev.type == "progress" and ev.job_id == cal_id:
                        placed["during"] = sim.specimen.brdf

                svc.add_event_listener(on_progress)
                cal_id = start_sim_calibration(
                    svc, sim, report=lambda j, st, _r: reports.append((j, st)))
                # Queued after the calibration, as a user's first scan would be.
                scan_id = svc.submit(JobRequest(plan=UniformPlan(specimen="sim", rotations=6))).id
                async for ev in svc.subscribe(0, job_id=scan_id):
                    if ev.type == "state" and ev.data["state"] in TERMINAL:
                        break
                return cal_id, scan_id
            finally:
                await svc.stop()

        cal_id, scan_id = asyncio.run(go())
        assert placed["during"] is not specimen  # the white reference was on the stage
        assert sim.specimen.brdf is specimen  # and the specimen is back
        assert reports == [(cal_id, "completed")]
        cal_job, scan_job = svc.get_job(cal_id), svc.get_job(scan_id)
        assert cal_job.state is JobState.COMPLETED, cal_job.reason
        assert scan_job.state is JobState.COMPLETED, scan_job.reason
        assert scan_job.started is not None and cal_job.finished is not None
        assert scan_job.result is not None and scan_job.result["calibrated"] is True
        assert cal_job.specimen == "white reference"  # what the job list shows for it

        # The calibration job's own readings were of the white reference: each pair's factor
        # turns them into albedo / pi.
        cal = Calibration.model_validate_json((data / "calibration.json").read_text())
        assert cal.reference_albedo == WHITE_REFERENCE_ALBEDO
        assert f"job {cal_id}" in cal.source
        ref = read_result(svc.result_path(cal_id))
        for r in ref.readings:
            f = cal.factor(r.light, r.sensor, 3) * (np.subtract(r.raw, r.dark))
            np.testing.assert_allclose(f, WHITE_REFERENCE_ALBEDO / math.pi, rtol=0.02)

        # The scan's samples are the specimen's true BRDF in 1/sr, within the sensor noise.
        res = read_result(svc.result_path(scan_id))
        s = res.samples
        truth = np.stack([[sim.true_brdf(a, b, ang) for ang in s.stage_angles_deg]
                          for a, b in s.pairs])
        np.testing.assert_allclose(s.values, truth, rtol=0.05, atol=0.005 * truth.max())
        # The result file records exactly the calibration that was applied.
        assert Calibration.model_validate(s.calibration) == cal
        assert Calibration.model_validate_json(res.provenance["calibration"]) == cal
        assert json.loads(res.provenance["plan"])["exposure"]["exposure_s"] == cal.exposure_s


def test_place_specimen_swaps_the_brdf_and_checks_channels() -> None:
    with start_sim_rig(SimRigOptions(noise=None)) as sim:
        before = sim.true_brdf("L1", "S1", 30.0)
        old = sim.place_white_reference(0.5)
        np.testing.assert_allclose(sim.true_brdf("L2", "S3", 123.0), 0.5 / math.pi)
        with pytest.raises(ValueError, match="albedo must be in"):
            sim.place_white_reference(1.5)
        from gonio.brdf.models.analytic import Lambert

        with pytest.raises(ValueError, match="the simulated sensors report 3"):
            sim.place_specimen(Lambert((0.5,), channels=("Y",)))
        sim.place_specimen(old.brdf)
        np.testing.assert_allclose(sim.true_brdf("L1", "S1", 30.0), before)
