"""What an export says about itself, read back from each format (issue 26 item 3)."""

from __future__ import annotations

import functools
import json
import math
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from gonio.brdf.materials import library
from gonio.brdf.models import analytic as bm
from gonio.brdf.models.factored import fit_factored, fit_metrics
from gonio.brdf.models.principled import Principled
from gonio.brdf.reconstruction.blas import one_blas_thread
from gonio.brdf.tables import geometry as geo
from gonio.brdf.tables.metrics import log_rmse
from gonio.brdf.tables.table import BRDFTable
from gonio.calibration import CalibratedScan
from gonio.cli import main
from gonio.cli.export_command import report
from gonio.export import (
    FIT_ITERATIONS,
    Fits,
    export_result,
    judge,
    merl,
    provenance,
    result_fits,
    write_export,
)
from gonio.export.metadata import (
    COLOUR_STATEMENT,
    TWOFOLD_WARN,
    export_provenance,
    specimen_name,
)
from gonio.results import write_result

PLAN = {"kind": "uniform", "specimen": "specimen", "rotations": 8, "span_deg": 180.0}
RIG = {"stage_min_deg": -180.0, "stage_max_deg": 180.0, "lights": [{"name": "L1"}],
       "sensors": [{"name": "S1"}], "pairs": [{"light": "L1", "sensor": "S1"}]}
CAL = {"pairs": [{"light": "L1", "sensor": "S1", "factor": [1.0, 1.0, 1.0]}],
       "reference_albedo": 0.99, "exposure_s": 0.01, "source": "job 3: spectralon-99",
       "created": "2026-11-20T08:00:00Z"}


def _samples() -> CalibratedScan:
    return CalibratedScan(pairs=[("L1", "S1")], light_dirs=np.array([[0.0, 0.0, 1.0]]),
                          sensor_dirs=np.array([[0.0, 0.0, 1.0]]),
                          stage_angles_deg=np.array([0.0]), values=np.ones((1, 1, 3)),
                          channels=("R", "G", "B"))


def library_principled(name: str) -> Principled:
    """A library conductor's own principled parameters, worked out from its definition: a
    GGX metal (``Rotated(GGX(alpha_x, alpha_y, ConductorFresnel(eta, k)))``) whose ``F0`` is
    the normal-incidence Fresnel reflectance ``((eta - 1)^2 + k^2) / ((eta + 1)^2 + k^2)``,
    the tangent its rougher axis."""
    m = library.get_material(name)
    ggx, fresnel = m.model, m.model.fresnel
    f0 = tuple(((e - 1) ** 2 + k**2) / ((e + 1) ** 2 + k**2)
               for e, k in zip(fresnel.eta, fresnel.k, strict=True))
    ax, ay, direction = ggx.alpha_x, ggx.alpha_y, math.degrees(m.angle)
    if ay > ax:
        ax, ay, direction = ay, ax, direction + 90.0
    return Principled(f0, 1.0, 0.5, ax, ay, direction)


def stand_in_fits(table: BRDFTable, principled: Principled) -> Fits:
    """Fits of ``table`` as a result stores them, without fitting the principled material:
    the factored fit as :func:`gonio.export.fit_all` makes it (with its rendered difference),
    and ``principled`` (the material's own parameters) recorded as a rendered fit (its table
    metrics, rendered difference and ``fit`` = "rendered", so that no export fits it again,
    :func:`gonio.export.result_fits`). For tests of what is stored and what an export says,
    which do not depend on how the principled parameters were found: fitting them costs
    seconds of CPU, and test_judge.py and test_export_command.py's refit test check the
    rendered fit itself."""
    with one_blas_thread():  # as fit_all runs it
        factored = fit_factored(table, iterations=FIT_ITERATIONS)
    factored = replace(factored, metrics={
        **factored.metrics, "rendered": judge.rendered_difference(table, factored).as_dict()})
    metrics: dict[str, Any] = dict(fit_metrics(bm.tabulate(principled.model(), np.float64),
                                               table))
    metrics.update(rendered=judge.rendered_difference(table, principled.model()).as_dict(),
                   fit="rendered")
    return Fits(table, factored, replace(principled, metrics=metrics))


@functools.cache
def _fitted(name: str) -> tuple[Any, Any]:
    """Library material ``name`` tabulated and its fits as a result stores them (the material
    does not matter here, only the record: :func:`stand_in_fits`), once per material in
    this module."""
    table = bm.tabulate(library.get_material(name))
    return table, stand_in_fits(table, library_principled(name))


def _result(path: Path, name: str, specimen: str, simulated: bool,
            **extra: str) -> Path:
    table, fits = _fitted(name)
    prov: dict[str, Any] = {"plan": json.dumps(PLAN), "rig": json.dumps(RIG),
                            "calibration": json.dumps(CAL), **extra}
    if simulated:
        prov["true_material"] = json.dumps({"library": name})
    return write_result(
        path, job_id=9, specimen=specimen, kind="uniform", readings=[], samples=_samples(),
        table=table, metrics={"predicted_error": 0.107, "predicted_log_rmse": 0.053},
        provenance=prov, factored=fits.factored, principled=fits.principled)


@pytest.fixture(scope="module")
def brushed(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A simulated scan's result of a brushed metal, scanned without a specimen name (the
    placeholder older gonio versions stored)."""
    return _result(tmp_path_factory.mktemp("r") / "job-9.h5", "brushed-metal-003", "specimen",
                   simulated=True)


def _check(meta: dict[str, Any]) -> None:
    assert meta["gonio_provenance"] == 1
    assert meta["reconstruction_error"]["predicted_log_rmse"] == pytest.approx(0.053)
    assert "cosine-weighted" in meta["reconstruction_error"]["meaning"]
    assert meta["specimen"] == "unnamed" and meta["specimen_named"] is False
    assert meta["source"] == "simulated" and meta["simulated_material"] == {
        "library": "brushed-metal-003"}
    assert meta["colour_space"] == COLOUR_STATEMENT
    assert "holder" in meta["orientation"]["specimen_frame"]
    assert "TANGENT.w = +1" in meta["orientation"]["mesh"]
    assert meta["calibration"]["reference"] == "job 3: spectralon-99"
    assert meta["calibration"]["date"] == "2026-11-20T08:00:00Z"
    assert meta["rig"]["lights"] == ["L1"] and meta["rig"]["n_pairs"] == 1
    assert meta["plan"]["rotations"] == 8
    rendered = meta["fits"]["principled"]["rendered"]
    assert rendered["metric"] in ("HDR-FLIP", "relative image error")
    assert 0 <= rendered["value"] < 1
    assert meta["fits"]["factored"]["rendered"]["value"] >= 0
    # A GGX brushed metal reads the same turned by half a turn: nothing for the principled
    # models to lose, and no warning about it.
    assert meta["symmetry"]["twofold_asymmetry"] < 1e-4
    assert "twofold symmetric" in meta["symmetry"]["formats"]
    assert not any("half-turn average" in w for w in meta["warnings"])


def test_gltf_carries_the_record(brushed: Path, tmp_path: Path) -> None:
    doc = json.loads(export_result(brushed, "gltf", tmp_path / "x.gltf").read_text())
    _check(doc["asset"]["extras"])
    _check(doc["materials"][0]["extras"])
    assert doc["materials"][0]["name"] == "unnamed_job9"


def test_mtlx_carries_the_record(brushed: Path, tmp_path: Path) -> None:
    import MaterialX

    doc = MaterialX.createDocument()
    MaterialX.readFromXmlFile(doc, str(export_result(brushed, "mtlx", tmp_path / "x.mtlx")))
    # the standard_surface material first, the open_pbr_surface one beside it: both carry it
    materials = [n for n in doc.getNodes() if n.getCategory() == "surfacematerial"]
    assert [m.getName().endswith("_openpbr") for m in materials] == [False, True]
    for material in materials:
        _check(json.loads(material.getDocString()))
        assert material.getAttribute("gonio_source") == "simulated"
        assert float(material.getAttribute("gonio_predicted_log_rmse")) == pytest.approx(0.053)
        assert material.getAttribute("gonio_colour_space") == COLOUR_STATEMENT


@pytest.mark.parametrize("fmt", ["factored", "table"])
def test_npz_formats_carry_the_record(brushed: Path, tmp_path: Path, fmt: str) -> None:
    path = export_result(brushed, fmt, tmp_path / f"x.{fmt}.npz")
    with np.load(path) as z:
        _check(json.loads(str(z["provenance"])))


def test_merl_sidecar_carries_the_record_and_the_averaging(brushed: Path, tmp_path: Path,
                                                           capsys: pytest.CaptureFixture[str]
                                                           ) -> None:
    out = tmp_path / "x.binary"
    assert main(["export", str(brushed), "-f", "merl", "-o", str(out)]) == 0
    side = json.loads(merl.sidecar_path(out).read_text())
    _check(side)
    assert side["merl"]["azimuthally_averaged"] is True
    # The brushed metal is far from its azimuthal average; the sidecar and the CLI say so.
    assert side["merl"]["anisotropy_lost"] > merl.ANISOTROPY_WARN
    assert any("anisotropic" in w for w in side["warnings"])
    text = capsys.readouterr().out
    assert "averaged over azimuth" in text and "warning:" in text and "anisotropic" in text
    assert "unnamed (no specimen name was given" in text


def test_isotropic_tables_lose_nothing_to_merl() -> None:
    table = bm.tabulate(bm.LobeSum((bm.Lambert((0.2, 0.3, 0.4)), bm.GGX(
        0.2, 0.2, bm.SchlickFresnel(0.04), "separable"))), np.float64)
    assert merl.anisotropy_lost(table) < 1e-6
    assert "warnings" not in merl.merl_sidecar(table, {})


def test_measured_and_named(tmp_path: Path) -> None:
    # The material does not matter here, only the provenance: the brushed metal's fits, made
    # once for the module's other tests, are reused.
    path = _result(tmp_path / "job-9.h5", "brushed-metal-003", "felt #2", simulated=False)
    meta = json.loads(export_result(path, "gltf", tmp_path / "x.gltf").read_text())
    extras = meta["asset"]["extras"]
    assert extras["source"] == "measured" and "simulated_material" not in extras
    assert extras["specimen"] == "felt #2" and extras["specimen_named"] is True


def test_the_record_carries_the_upper_end_of_the_estimate_when_stored() -> None:
    with_upper = export_provenance({}, {"predicted_log_rmse": 0.04,
                                        "predicted_log_rmse_upper": 0.08}, {}, {})
    assert with_upper["reconstruction_error"]["predicted_log_rmse_upper"] == 0.08
    # A result made before the interval was stored (or by V&F's path, null) has none.
    for metrics in ({"predicted_log_rmse": 0.04},
                    {"predicted_log_rmse": 0.04, "predicted_log_rmse_upper": None}):
        rec_error = export_provenance({}, metrics, {}, {})["reconstruction_error"]
        assert "predicted_log_rmse_upper" not in rec_error


def test_the_record_carries_the_layouts_mirror_gap_when_stored() -> None:
    note = "no pair's half vector comes within 7.5 degrees of the specimen normal ..."
    gapped = export_provenance({}, {"predicted_log_rmse": 0.04, "mirror_gap_deg": 7.5,
                                    "mirror_gap": note}, {}, {})["reconstruction_error"]
    assert gapped["mirror_gap_deg"] == 7.5 and gapped["mirror_gap"] == note
    on_mirror = export_provenance({}, {"predicted_log_rmse": 0.04, "mirror_gap_deg": 0.0},
                                  {}, {})["reconstruction_error"]
    assert on_mirror["mirror_gap_deg"] == 0.0 and "mirror_gap" not in on_mirror
    older = export_provenance({}, {"predicted_log_rmse": 0.04}, {}, {})["reconstruction_error"]
    assert "mirror_gap_deg" not in older and "mirror_gap" not in older


def test_specimen_names() -> None:
    assert specimen_name(None) == ("unnamed", False)
    assert specimen_name("  ") == ("unnamed", False)
    assert specimen_name("specimen") == ("unnamed", False)  # older gonio's silent placeholder
    assert specimen_name("copper 3") == ("copper 3", True)


def test_an_asymmetric_result_says_what_the_principled_models_lose(
        brushed: Path, tmp_path: Path) -> None:
    """Issue 25 item 3: a result without twofold symmetry exported to a symmetric model."""
    sym = bm.tabulate(library.get_material("brushed-metal-003"), np.float64)
    # f (1 + 0.6 cos ph): the cos ph harmonic changes sign under a half turn, so the
    # half-turn average of the table is exactly ``sym`` again.
    tilt = 1.0 + 0.6 * np.cos(geo.PH_GRID)[None, :, None, None, None]
    table = BRDFTable.trusted(np.asarray(sym.values) * tilt, sym.channels, "tilted")
    # The brushed result's stored fits stand in for the tilted table's (fitting takes a
    # minute on a busy machine, and what is checked here is the table's symmetry record).
    stored, _ = result_fits(brushed)
    fits = Fits(table, stored.factored, stored.principled)
    prov = provenance({"job_id": 9, "specimen": "tilted pile"}, fits, {}, {})
    out = write_export(fits, "gltf", tmp_path / "x.gltf", prov)
    meta = json.loads(out.read_text())["asset"]["extras"]
    assert meta["symmetry"]["twofold_asymmetry"] == pytest.approx(log_rmse(sym, table),
                                                                  rel=1e-6)
    assert meta["symmetry"]["twofold_asymmetry"] > TWOFOLD_WARN
    assert any("not twofold symmetric" in w for w in meta["warnings"])
    assert any("warning: the result is not twofold symmetric" in line
               for line in report("gltf", out, prov))
    # The factored model and the table keep what differs at ph + 180 deg: the warning is not
    # theirs.
    factored = write_export(fits, "factored", tmp_path / "x.factored.npz", prov)
    with np.load(factored) as z:
        assert not any("not twofold symmetric" in w
                       for w in json.loads(str(z["provenance"]))["warnings"])


def test_a_calibration_at_another_exposure_is_among_the_export_warnings(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    # A scan at 0.5 s with a calibration taken at 0.01 s is 50 times off. The record's
    # calibration.warning said so, but the warnings gonio export prints (and the daemon's
    # X-Gonio-Export-Warnings header) left it out while they listed the physical-bounds
    # warning that mismatch caused.
    warning = ("the calibration was measured at exposure 0.01 s, this scan at 0.5 s; its "
               "values are off by about the ratio. Calibrate at the scan's exposure")
    path = _result(tmp_path / "job-9.h5", "brushed-metal-003", "felt", simulated=False,
                   calibration_warning=warning)
    assert main(["export", str(path), "--format", "gltf", "-o", str(tmp_path / "x.gltf")]) == 0
    assert f"warning: {warning}" in capsys.readouterr().out
    extras = json.loads((tmp_path / "x.gltf").read_text())["asset"]["extras"]
    assert extras["calibration"]["warning"] == warning and warning in extras["warnings"]


def test_the_table_export_says_the_reconstructions_own_warnings(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    # "outside physical bounds ... do not use this table without checking it" was printed
    # with the gltf, mtlx, merl and factored exports, and not with the table's (nor in its
    # file): the one export it is about. The fits' warnings stay off the table.
    bounds = ("the reconstruction is outside physical bounds: its directional albedo reaches "
              "18.1; do not use this table without checking it")
    path = _result(tmp_path / "job-9.h5", "brushed-metal-003", "felt", simulated=False,
                   physical_bounds=bounds)
    out = tmp_path / "x.table.npz"
    assert main(["export", str(path), "--format", "table", "-o", str(out)]) == 0
    printed = capsys.readouterr().out
    assert f"warning: {bounds}" in printed
    with np.load(out) as z:
        meta = json.loads(str(z["provenance"]))
    assert meta["warnings"] == [bounds] == meta["reconstruction_warnings"]
    assert main(["export", str(path), "--format", "gltf", "-o", str(tmp_path / "x.gltf")]) == 0
    assert f"warning: {bounds}" in capsys.readouterr().out


def test_an_uncalibrated_scan_is_exported_saying_its_values_are_sensor_units(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    # A first scan before any white reference: its exports' colour_space said "each scaled to
    # 1/sr by a white reference" and nothing printed or stored said the values were sensor
    # units (the MaterialX base_color came out 1, 1, 1).
    from gonio.export.metadata import UNCALIBRATED_COLOUR_STATEMENT, UNCALIBRATED_WARNING

    none = json.dumps({"pairs": [], "source": "none"})
    path = _result(tmp_path / "job-9.h5", "brushed-metal-003", "felt", simulated=False,
                   calibration=none)
    assert main(["export", str(path), "--format", "gltf", "-o", str(tmp_path / "x.gltf")]) == 0
    assert f"warning: {UNCALIBRATED_WARNING}" in capsys.readouterr().out
    extras = json.loads((tmp_path / "x.gltf").read_text())["asset"]["extras"]
    assert extras["colour_space"] == UNCALIBRATED_COLOUR_STATEMENT
    assert "1/sr by a white reference" not in extras["colour_space"]
    assert extras["calibration"]["calibrated"] is False
    assert extras["reconstruction_warnings"][0] == UNCALIBRATED_WARNING
    out = tmp_path / "x.table.npz"  # the table too: imported, it would train the basis
    assert main(["export", str(path), "--format", "table", "-o", str(out)]) == 0
    with np.load(out) as z:
        assert json.loads(str(z["provenance"]))["warnings"] == [UNCALIBRATED_WARNING]
    # A calibrated result, and an older one that records no calibration, say nothing of it.
    calibrated = export_provenance({}, {}, {"calibration": json.dumps(CAL)}, {})
    older = export_provenance({}, {}, {}, {})
    for meta in (calibrated, older):
        assert meta["colour_space"] == COLOUR_STATEMENT and not meta["warnings"]


def test_the_merl_export_carries_the_reconstructions_warnings_not_the_fits(
        brushed: Path, tmp_path: Path) -> None:
    # A metallic paint's MERL export printed and stored "the factored fit renders visibly
    # unlike the reconstruction ...; use the 'table' export": the MERL file is the table
    # averaged over azimuth, no fit at all. It keeps the reconstruction's own warnings.
    from gonio.export import export_warnings

    fits, prov = result_fits(brushed)
    fit_said = ("the factored fit renders visibly unlike the reconstruction (HDR-FLIP 0.277 > "
                "0.25): this model does not represent the material well; use the 'table' "
                "export where a renderer can take a table")
    recon_said = "the highlight is not read: the reconstruction peaks 3.91 times above"
    prov = {**prov, "warnings": [fit_said, recon_said], "reconstruction_warnings": [recon_said]}
    out = write_export(fits, "merl", tmp_path / "x.binary", prov)
    said = export_warnings("merl", out, prov)
    assert recon_said in said and fit_said not in said
    assert json.loads((tmp_path / "x.binary.json").read_text())["warnings"] == said


def test_each_fitted_export_carries_its_own_models_warnings(
        brushed: Path, tmp_path: Path) -> None:
    # A metallic paint's glTF file (the principled fit) said "the factored fit renders
    # visibly unlike the reconstruction ... use the 'table' export": a warning about a model
    # the file does not hold. Each fitted format carries its own model's warnings and the
    # reconstruction's; the file holds no other model's.
    from gonio.export import MODEL_WARNINGS, export_warnings

    fits, prov = result_fits(brushed)
    principled_said = "the principled fit renders visibly unlike the reconstruction (x)"
    factored_said = "the factored fit renders visibly unlike the reconstruction (y)"
    recon_said = "the highlight is not read: the reconstruction peaks 3.91 times above"
    prov = {**prov, "warnings": [principled_said, factored_said, recon_said],
            "reconstruction_warnings": [recon_said],
            MODEL_WARNINGS: {"principled": [principled_said], "factored": [factored_said]}}
    gltf = write_export(fits, "gltf", tmp_path / "x.gltf", prov)
    extras = json.loads(gltf.read_text())["asset"]["extras"]
    assert extras["warnings"] == [principled_said, recon_said]
    assert export_warnings("gltf", gltf, prov) == [principled_said, recon_said]
    assert MODEL_WARNINGS not in extras
    assert export_warnings("mtlx", tmp_path / "x.mtlx", prov) == [principled_said, recon_said]
    factored = write_export(fits, "factored", tmp_path / "x.factored.npz", prov)
    with np.load(factored) as z:
        meta = json.loads(str(z["provenance"]))
    assert meta["warnings"] == [factored_said, recon_said]
    assert export_warnings("factored", factored, prov) == [factored_said, recon_said]
    # A record an older gonio made has no per-model warnings: its list is kept whole.
    older = {k: v for k, v in prov.items() if k != MODEL_WARNINGS}
    assert export_warnings("gltf", gltf, older) == older["warnings"]
