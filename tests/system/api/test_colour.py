"""Colour end to end: a spectral specimen on the simulated rig, scanned by 31-band sensors over
the real protocols, calibrated against the white reference, gives CIELAB at instrument
geometries in its result file; the HTTP route serves a result's colour."""

from __future__ import annotations

import asyncio
import csv
import io
import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from gonio.basis_supply import BasisSupply
from gonio.brdf.colour.conditions import ViewingConditions, delta_e00, spectra_to_xyz, xyz_to_lab
from gonio.brdf.colour.instruments import geometries
from gonio.cli.sim_session import start_sim_calibration
from gonio.drivers.factory import build_rig
from gonio.jobstates import JobState
from gonio.plans.models import UniformPlan
from gonio.result_colour import result_report
from gonio.results import read_result
from gonio.service import GonioService, JobRequest
from gonio.sim.rig import SimRigOptions, start_sim_rig
from gonio.store import JobStore
from tests.system.api.conftest import Daemon
from tests.system.api.test_scan_flow import scan, wait_state

pytestmark = pytest.mark.system

TERMINAL = ("completed", "failed", "aborted", "halted")


def test_spectral_sim_scan_gives_cielab(tmp_path: Path, basis: Any) -> None:
    data = tmp_path / "data"
    opts = SimRigOptions(material="yellow-plastic", time_scale=10.0, settle_s=0.0, seed=3)
    with start_sim_rig(opts) as sim:
        # The simulated sensors are a 31-band spectrometer, and the rig config says so.
        assert sim.config.sensors[0].wavelengths_nm == list(np.arange(400.0, 701.0, 10.0))
        specimen = sim.specimen.brdf
        svc = GonioService(JobStore(tmp_path / "jobs.sqlite"), build_rig(sim.config),
                           rig_config=sim.config, basis=BasisSupply(lambda: basis), data_dir=data)

        async def go() -> int:
            await svc.start()
            try:
                start_sim_calibration(svc, sim)
                scan_id = svc.submit(JobRequest(plan=UniformPlan(specimen="yellow plastic",
                                                                 rotations=6))).id
                async for ev in svc.subscribe(0, job_id=scan_id):
                    if ev.type == "state" and ev.data["state"] in TERMINAL:
                        break
                return scan_id
            finally:
                await svc.stop()

        scan_id = asyncio.run(go())
        job = svc.get_job(scan_id)
        assert job.state is JobState.COMPLETED, job.reason
        res = read_result(svc.result_path(scan_id))
    assert res.table is not None and len(res.table.channels) == 31
    assert res.table.wavelengths_nm == tuple(np.arange(400.0, 701.0, 10.0))
    stored = res.colour or {}
    assert stored["source"]["bands"]["centres_nm"][0] == 400.0
    report = stored["report"]
    assert report["space"] == "CIELAB" and report["conditions"]["illuminant"] == "D65"
    assert report["conditions"]["observer"] == "10"
    # Against the true material's colour at the MA98 geometries, straight from its spectral
    # BRDF (no bands, no reconstruction). The test's basis is small (K = 8, 6 materials): the
    # bound is loose; the benchmark measures the real accuracy.
    cond = ViewingConditions()
    g = geometries(["MA98"])
    wi = np.stack([x.directions()[0] for x in g])
    wo = np.stack([x.directions()[1] for x in g])
    truth = xyz_to_lab(spectra_to_xyz(np.pi * specimen.spectral_eval(wi, wo), cond), cond)
    ma98 = [r for r in report["rows"] if r["instrument"] == "MA98"]
    got = np.array([[r["L"], r["a"], r["b"]] for r in ma98])
    de = delta_e00(got, truth)
    assert np.median(de) < 5.0, de
    # The hue is the material's: a yellow (b* far above a*) at the diffuse geometries.
    assert all(r["b"] > 30 and abs(r["a"]) < 15 for r in ma98 if r["aspecular_deg"] >= 45)
    # Read back through the result file's source, the same numbers.
    again = result_report(res, cond, ["MA98"])
    assert again.lab is not None and again.lab == pytest.approx(got, abs=1e-6)
    # The export fits are made of the linear sRGB table (from XYZ), not of the first three
    # bands: a glTF export is a yellow, the table export keeps the 31 bands.
    assert res.factored is not None and res.factored.channels == ("R", "G", "B")
    from gonio.export import result_fits, write_export

    # Both exports from one reading of the result's fits and provenance, as export_result
    # makes each (check_format, result_fits, write_export): the 31-band file is read once.
    fits, prov = result_fits(svc.result_path(scan_id))
    gltf = write_export(fits, "gltf", tmp_path / "y.gltf", prov)
    base = json.loads(gltf.read_text())["materials"][0]["pbrMetallicRoughness"][
        "baseColorFactor"]
    assert base[0] > base[2] * 2 and base[1] > base[2] * 1.5, base  # R, G well above B
    stated = json.loads(gltf.read_text())["asset"]["extras"]["colour_space"]
    assert stated.startswith("linear sRGB") and "D65/10" in stated and "spectral bands" in stated
    table = write_export(fits, "table", tmp_path / "y.npz", prov)
    from gonio.brdf.tables.table import BRDFTable

    kept = BRDFTable.load(table)
    assert kept.wavelengths_nm == tuple(np.arange(400.0, 701.0, 10.0))
    # The bands are not sRGB, and the table's record says so instead of the fits' sRGB.
    assert kept.provenance["colour_space"].startswith("the reconstruction's own channels (400")
    # MERL holds R, G, B: the same linear sRGB as the glTF (it was refused: 31 channels).
    from gonio.brdf.materials.imports import read_merl_table
    from gonio.export.merl import sidecar_path

    merl = write_export(fits, "merl", tmp_path / "y.binary", prov)
    side = json.loads(sidecar_path(merl).read_text())
    assert side["colour_space"] == stated
    back = read_merl_table(merl)
    assert back.channels == ("R", "G", "B")
    # At a diffuse geometry (light and view 30 degrees from the normal, a quarter turn
    # apart), the material's yellow: R and G well above B, as in the glTF.
    c, n = np.cos(np.radians(30)), np.sin(np.radians(30))
    rgb = back.eval(np.array([[n, 0.0, c]]), np.array([[0.0, n, c]]))[0]
    assert rgb[0] > rgb[2] * 2 and rgb[1] > rgb[2] * 1.5, rgb


def test_colour_route(daemon: Daemon, no_export_fits: None) -> None:
    with daemon.client() as c:
        r = c.post("/api/v1/jobs", json=scan("panel", rotations=4))
        assert r.status_code == 201, r.text
        job_id = r.json()["id"]
        done = wait_state(c, job_id, {"completed", "failed"}, timeout=180)
        assert done["state"] == "completed", done
        got = c.get(f"/api/v1/jobs/{job_id}/colour", params={"instrument": ["MA68"],
                                                             "azimuth": [0, 90]})
        assert got.status_code == 200, got.text
        body = got.json()["colour"]
        # The shared daemon's rig has RGB sensors and no white reference: no CIELAB, and the
        # answer says so instead of pretending its values are sRGB.
        assert body["space"] == "uncalibrated sensor RGB"
        assert len(body["rows"]) == 10 and "L" not in body["rows"][0]
        # Channel values depend on no illuminant or observer: the answer names none.
        assert body["conditions"] is None and "illuminant" not in body["provenance"]
        text = c.get(f"/api/v1/jobs/{job_id}/colour", params={"format": "csv"})
        assert text.status_code == 200 and text.headers["content-type"].startswith("text/csv")
        # Named after the job and its specimen, as the result file and the exports are.
        assert text.headers["content-disposition"] == (
            f'attachment; filename="gonio-job-{job_id}-panel-colour.csv"')
        rows = list(csv.DictReader(io.StringIO(text.text)))
        assert rows[0]["space"] == "uncalibrated sensor RGB" and len(rows) == 17
        assert {(r["illuminant"], r["observer"]) for r in rows} == {("", "")}
        bad = c.get(f"/api/v1/jobs/{job_id}/colour", params={"illuminant": "D66"})
        assert bad.status_code == 422 and "unknown illuminant" in bad.json()["detail"]
        bad = c.get(f"/api/v1/jobs/{job_id}/colour", params={"instrument": ["MA99"]})
        assert bad.status_code == 422 and "known instruments" in bad.json()["detail"]
        # Why there is no CIELAB, hence no ΔE00, and what to do: said, not left to a missing
        # difference. The rig's sensors would not matter: its values are not in 1/sr.
        why = got.json()["no_colour"]
        assert why.startswith(f"job {job_id} is uncalibrated: its values are sensor units, "
                              "not 1/sr"), why
        assert "calibrate the rig on the white reference" in why and "scan the specimen " \
            "again" in why, why
        vs = c.get(f"/api/v1/jobs/{job_id}/colour", params={"against": job_id})
        assert vs.status_code == 422
        assert vs.json()["detail"] == f"no ΔE00 against job {job_id}: {why}"
        assert c.get("/api/v1/jobs/999999/colour").status_code == 404
