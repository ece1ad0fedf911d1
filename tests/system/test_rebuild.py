"""``gonio jobs rebuild`` writes what the original finishing wrote (gonio.finishing.rebuild_result).

A scan on the simulated rig (31-band spectral sensors, so its colour comes from the rig
config) whose rig config carries a ``[design]`` table is finished by the worker; its result file
is deleted and rebuilt from the job store's readings in another store handle, as the CLI does.
Every group, dataset and attribute of the original is in the rebuilt file, with the same design
comparison, colour report and self-estimate (its coverage witness among the metrics). Then
the same job as an older gonio left it (no `finishing` table, a result file written by hand):
the rig config comes from that file, and with it the design comparison and the colour.
"""

from __future__ import annotations

import asyncio
import json
import shutil
import sqlite3
from pathlib import Path
from typing import Any

import h5py
import numpy as np
import pytest

from gonio.basis_supply import BasisSupply
from gonio.cli.sim_session import start_sim_calibration
from gonio.config import DesignExpectation
from gonio.drivers.factory import build_rig
from gonio.finishing import rebuild_result
from gonio.plans.models import UniformPlan
from gonio.service import GonioService, JobRequest
from gonio.sim.rig import SimRigOptions, start_sim_rig
from gonio.store import JobStore
from tests.unit.brdf.reconstruction.test_basis import small_basis

pytestmark = [pytest.mark.system, pytest.mark.timeout(600)]

TERMINAL = ("completed", "failed", "aborted", "halted")
# Far below any real scan's self-estimate, so the comparison says why (a design_gap).
DESIGN = DesignExpectation(expected_log_rmse=1e-4, rotations=4, span_deg=180.0, pairs=3,
                           calibrated=True)
# What differs between two finishings of the same readings: when and how fast they ran.
VOLATILE = {("/", "created"), ("/", "gonio_version"), ("/provenance", "rebuilt")}


def _layout(path: Path) -> dict[tuple[str, str], Any]:
    """Every (object, attribute) of an HDF5 file with its value, and every dataset's shape."""
    out: dict[tuple[str, str], Any] = {}
    with h5py.File(path, "r") as f:
        def visit(name: str, obj: Any) -> None:
            key = "/" + name if name else "/"
            for a, v in obj.attrs.items():
                out[(key, a)] = v.decode() if isinstance(v, bytes) else v
            if isinstance(obj, h5py.Dataset):
                out[(key, "<shape>")] = obj.shape

        visit("", f)
        f.visititems(visit)
    return out


def _timeless(x: Any) -> Any:
    """JSON without its "seconds" entries (a fit's or reconstruction's own duration)."""
    if isinstance(x, dict):
        return {k: _timeless(v) for k, v in x.items() if k != "seconds"}
    if isinstance(x, list):
        return [_timeless(v) for v in x]
    return x


def test_a_rebuilt_result_holds_the_design_comparison_colour_and_coverage(tmp_path: Path
                                                                          ) -> None:
    basis = small_basis()
    data = tmp_path / "data"
    with start_sim_rig(SimRigOptions(material="yellow-plastic", time_scale=10.0, settle_s=0.0,
                                     seed=5)) as sim:
        assert sim.config.sensors[0].wavelengths_nm  # spectral: colour from the rig config
        config = sim.config.model_copy(update={"design": DESIGN})
        svc = GonioService(JobStore(data / "gonio.sqlite"), build_rig(sim.config),
                           rig_config=config, basis=BasisSupply(lambda: basis), data_dir=data,
                           fit_exports=False)  # a rebuild with fits: test_disk_full.py

        async def go() -> int:
            await svc.start()
            try:
                start_sim_calibration(svc, sim)
                job = svc.submit(JobRequest(plan=UniformPlan(specimen="yellow plastic",
                                                             rotations=4))).id
                async for ev in svc.subscribe(0, job_id=job):
                    if ev.type == "state" and ev.data["state"] in TERMINAL:
                        break
                return job
            finally:
                await svc.stop()

        job = asyncio.run(go())
    row = svc.store.get_job(job)
    assert row.state.value == "completed", row.reason
    result = data / "results" / f"job-{job}.h5"
    original = Path(shutil.copyfile(result, tmp_path / "original.h5"))
    old = _layout(original)
    # What the original finishing wrote from the rig config: the design comparison and the
    # colour of spectral bands (a report, not an error).
    assert old[("/metrics", "design_expected_log_rmse")] == DESIGN.expected_log_rmse
    assert "design_gap" in {a for _, a in old}
    assert "bands" in json.loads(old[("/colour", "source")])
    assert ("/colour", "report") in old
    uncovered = old[("/metrics", "uncovered_share")]
    assert 0.0 < uncovered < 1.0
    assert row.summary is not None and row.summary["uncovered_share"] == uncovered

    result.unlink()
    # As gonio jobs rebuild: its own store handle and basis supply, no rig config at hand.
    store = JobStore(data / "gonio.sqlite", durable=False)
    summary = rebuild_result(store, data, job, BasisSupply(lambda: basis))
    new = _layout(result)
    assert set(new) - VOLATILE == set(old) - VOLATILE
    for key in sorted(set(old) - VOLATILE):
        a, b = old[key], new[key]
        if key[1] == "seconds":
            continue  # how long the finishing took
        if isinstance(a, str) and a[:1] in "{[":
            assert _timeless(json.loads(a)) == _timeless(json.loads(b)), key
        elif isinstance(a, np.ndarray | float | np.floating):
            np.testing.assert_allclose(a, b, rtol=1e-6, err_msg=str(key))
        else:
            assert a == b, key
    assert summary["design_gap"] == row.summary["design_gap"]
    assert summary["uncovered_share"] == uncovered
    with h5py.File(original) as f, h5py.File(result) as g:
        np.testing.assert_allclose(g["reconstruction/values"][()],
                                   f["reconstruction/values"][()], rtol=1e-5, equal_nan=True)

    # The same job as an older gonio left it: its store had no `finishing` table (dropped
    # here; opening the store creates it empty), and its result file is as docs/engine.md's
    # "Result file" lays it out, written here by hand, with the rig config in /provenance.
    # (Without that file: tests/unit/test_finishing.py.)
    store.close()
    with sqlite3.connect(data / "gonio.sqlite") as con:
        con.execute("DROP TABLE finishing")
    store = JobStore(data / "gonio.sqlite", durable=False)
    assert store.finishing_inputs(job) is None
    _older_result(result, job, rig_config=config.model_dump_json())
    older = rebuild_result(store, data, job, BasisSupply(lambda: basis))
    assert older["design_expected_log_rmse"] == DESIGN.expected_log_rmse
    assert older["design_gap"] == row.summary["design_gap"]
    assert "design_comparison" not in older
    with h5py.File(result) as f:
        assert "as it was before this rebuild" in f["provenance"].attrs["rig_config_from"]
        assert "bands" in json.loads(f["colour"].attrs["source"])  # the colour came back too


def _older_result(path: Path, job: int, rig_config: str) -> None:
    """A result file with the groups and root attributes of docs/engine.md's layout and the
    /provenance attributes an older gonio wrote (plan, rig, rig_config, calibration)."""
    with h5py.File(path, "w") as f:
        f.attrs.update(format="gonio-result", version=1, gonio_version="0.9.0", job_id=job,
                       specimen="yellow plastic", kind="specimen",
                       created="2026-01-05T10:00:00Z")
        for group in ("raw", "samples", "reconstruction", "metrics"):
            f.create_group(group)
        f["metrics"].attrs["predicted_log_rmse"] = 0.05
        p = f.create_group("provenance")
        p.attrs.update(plan=json.dumps({"kind": "uniform"}), rig=json.dumps({}),
                       rig_config=rig_config, calibration=json.dumps({"pairs": {}}))
