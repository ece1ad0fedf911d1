"""Figures' data: the true material's recipe and back, the headline error in words, and the
fit and polar curves of a result whose BRDF is known in closed form (a constant table and a
Lambertian truth, f = albedo / pi). The physical-bounds warning of the headline:
tests/unit/test_physical_bounds_report.py; colour renderings: tests/unit/test_result_colour.py.
"""

from __future__ import annotations

import functools
import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from gonio.brdf.models import analytic as bm
from gonio.brdf.pictures import render
from gonio.brdf.tables import geometry as geo
from gonio.brdf.tables.table import BRDFTable, from_function
from gonio.calibration import CalibratedScan
from gonio.figures import (
    TRUE_MATERIAL_KEY,
    FigureError,
    describe_material,
    fit_curves,
    headline_error,
    load_input,
    material_from_description,
    polar_curves,
    render_inputs,
    true_material,
)
from gonio.results import read_result, write_result

VALUE = (0.1, 0.2, 0.05)  # the constant table, 1/sr per channel
LAMBERT = bm.Lambert((0.3, 0.6, 0.9), name="paper")


@functools.cache
def _table() -> BRDFTable:
    return from_function(lambda i, o: np.tile(VALUE, (i.shape[0], 1)), ["R", "G", "B"], "flat")


@pytest.fixture(scope="module")
def npz(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("table") / "t.npz"
    _table().save(path)
    return path


def _dir(theta_deg: float, phi_deg: float) -> list[float]:
    t, p = math.radians(theta_deg), math.radians(phi_deg)
    return [math.sin(t) * math.cos(p), math.sin(t) * math.sin(p), math.cos(t)]


def _result(tmp: Path, table: BRDFTable | None = None, calibrated: bool = True,
            truth: Any = LAMBERT, kind: str = "uniform") -> Path:
    cal = {"pairs": [{"light": "L1", "sensor": "S1", "factor": [1, 1, 1]}]} if calibrated \
        else {"pairs": []}
    values = np.array([[[0.3, 0.3, 0.3], [0.6, 0.6, 0.6], [0.9, 0.9, 0.9]]])  # (1, 3, 3)
    s = CalibratedScan(pairs=[("L1", "S1")], light_dirs=np.array([_dir(45, 0)]),
                       sensor_dirs=np.array([_dir(30, 180)]),
                       stage_angles_deg=np.array([370.0, 90.0, 200.0]), values=values,
                       channels=("R", "G", "B"), calibration=cal)
    prov = {TRUE_MATERIAL_KEY: json.dumps(describe_material(truth))} if truth else {}
    return write_result(tmp / "r.h5", job_id=4, specimen="card", kind=kind, readings=[],
                        samples=s, table=table, provenance=prov)


def test_an_analytic_material_is_written_down_and_rebuilt() -> None:
    desc = describe_material(LAMBERT)
    assert desc is not None and desc["name"] == "paper"
    again = material_from_description(json.loads(json.dumps(desc)))
    wi, wo = np.array([_dir(30, 0)]), np.array([_dir(50, 120)])
    np.testing.assert_allclose(again.eval(wi, wo), [[0.3 / math.pi, 0.6 / math.pi,
                                                     0.9 / math.pi]])


def test_what_cannot_be_written_down_is_none(npz: Path) -> None:
    assert describe_material(object()) is None
    assert describe_material(_table()) is None  # a table with no file behind it
    loaded = BRDFTable.load(npz)
    assert describe_material(loaded) == {"name": "flat", "table_file": str(npz)}


def test_a_recipe_that_cannot_be_rebuilt_says_why(tmp_path: Path) -> None:
    with pytest.raises(FigureError, match="has neither a model nor a table"):
        material_from_description({"name": "x"})
    with pytest.raises(FigureError, match="the true material 'gone' cannot be rebuilt: "):
        material_from_description({"name": "gone", "table_file": str(tmp_path / "no.npz")})


def test_the_headline_error_in_words() -> None:
    log = headline_error({"predicted_log_rmse": 0.12345, "predicted_error": 0.5})
    assert log is not None and (log["key"], log["text"]) == ("predicted_log_rmse", "0.123")
    assert "0 is a perfect match" in log["meaning"]
    rel = headline_error({"predicted_error": 0.0567})
    assert rel is not None and (rel["key"], rel["value"], rel["text"]) == (
        "predicted_error", 0.0567, "5.7 %")
    assert headline_error({}) is None
    assert headline_error({"predicted_log_rmse": None}) is None


def test_the_headline_states_the_coverage_of_the_self_estimate() -> None:
    covered = headline_error({"predicted_log_rmse": 0.05, "uncovered_share": 0.0213})
    assert covered is not None and covered["uncovered_share"] == 0.0213
    assert "leave 2.1 % of the prior's weighted variance uncovered" in covered["coverage"]
    assert covered["meaning"].endswith(covered["coverage"])
    # V&F's path has none (null), and a MAPE headline is not the estimate it witnesses.
    for metrics in ({"predicted_log_rmse": 0.05, "uncovered_share": None},
                    {"predicted_error": 0.1, "uncovered_share": 0.02}):
        h = headline_error(metrics)
        assert h is not None and "coverage" not in h and "uncovered_share" not in h


def test_the_headline_states_the_upper_end_of_the_estimate() -> None:
    h = headline_error({"predicted_log_rmse": 0.05, "predicted_log_rmse_upper": 0.1})
    assert h is not None and h["upper"] == 0.1 and h["text"] == "0.050"
    assert "Upper end of its interval: 0.100" in h["interval"]
    assert h["meaning"].endswith(h["interval"])
    # V&F's path stores none (null); a MAPE headline has no such interval.
    for metrics in ({"predicted_log_rmse": 0.05, "predicted_log_rmse_upper": None},
                    {"predicted_error": 0.1, "predicted_log_rmse_upper": 0.2}):
        h = headline_error(metrics)
        assert h is not None and "interval" not in h and "upper" not in h


def test_the_headline_names_the_local_prior_the_fit_leaned_on() -> None:
    h = headline_error({"predicted_log_rmse": 0.05, "local_prior": "rgl-acrylic_felt_green"})
    assert h is not None and h["local_prior"] == "rgl-acrylic_felt_green"
    assert "leaned on the shape of 'rgl-acrylic_felt_green'" in h["prior"]
    assert h["meaning"].endswith(h["prior"])
    # No lean (the library's prior alone), or a MAPE headline: nothing said.
    for metrics in ({"predicted_log_rmse": 0.05},
                    {"predicted_error": 0.1, "local_prior": "rgl-acrylic_felt_green"}):
        h = headline_error(metrics)
        assert h is not None and "prior" not in h and "local_prior" not in h


def test_the_headline_says_which_arc_and_warns_a_half_turn_that_is_not_symmetric() -> None:
    base = {"predicted_log_rmse": 0.05}
    auto = headline_error({**base, "arc_symmetric": False, "arc_deg": 360.0,
                           "arc_test_statistic": 812.4, "arc_test_dof": 72,
                           "arc_test_p_value": 0.0})
    assert auto is not None and auto["text"] == "0.050"
    assert "over a full turn" in auto["arc"] and "not twofold symmetric" in auto["arc"]
    assert "812.4 on 72" in auto["arc"] and auto["meaning"].endswith(auto["arc"])
    forced = headline_error({**base, "arc_asymmetric": "the plan was forced over half a turn"})
    assert forced is not None and forced["text"].endswith("(NOT TWOFOLD SYMMETRIC)")
    assert forced["meaning"].startswith("Warning: the plan was forced over half a turn")
    assert "arc" not in (headline_error(base) or {})


def test_fit_curves_of_a_flat_table(tmp_path: Path) -> None:
    fit = fit_curves(read_result(_result(tmp_path, _table())), step_deg=90.0)
    assert fit["units"] == "1/sr" and fit["calibrated"] is True
    assert fit["channels"] == "mean of R, G, B"
    assert fit["curve_deg"] == [0.0, 90.0, 180.0, 270.0, 360.0]
    (pair,) = fit["pairs"]
    assert pair["label"] == "L1/S1"
    # stage angles taken modulo 360 and sorted, the readings with them
    assert pair["stage_deg"] == [10.0, 90.0, 200.0]
    assert pair["measured"] == pytest.approx([0.3, 0.6, 0.9])
    assert pair["curve"] == pytest.approx([sum(VALUE) / 3] * 5)


def test_polar_curves_of_a_flat_table_and_its_lambertian_truth(tmp_path: Path) -> None:
    polar = polar_curves(read_result(_result(tmp_path, _table())), 30.0, 0.0)
    assert polar["angle_deg"] == [float(a) for a in range(-89, 90)]
    assert polar["truth_name"] == "paper"
    for plane in ("in_plane", "cross_plane"):
        rec = polar["reconstruction"][plane]
        assert rec["G"][89] == pytest.approx(VALUE[1])  # at 0 deg: the normal, or the mirror
        truth = polar["truth"][plane]
        assert truth["B"] == pytest.approx([0.9 / math.pi] * 179)


def _lobe_table() -> BRDFTable:
    """A highlight over a diffuse body, three channels; NaN at the grid's invalid cells."""
    def f(i: np.ndarray, o: np.ndarray) -> np.ndarray:
        h = (i + o) / np.linalg.norm(i + o, axis=1, keepdims=True)
        return (0.05 + 20.0 * np.exp(-(1.0 - h[:, 2]) / 0.005))[:, None] * np.array(
            [1.0, 0.7, 0.4])

    return from_function(f, ["R", "G", "B"], "lobe")


def test_curves_are_the_whole_tables_lookup_at_each_pairs_directions(tmp_path: Path) -> None:
    # fit_curves and polar_curves look up only the nodes their points read
    # (render.TableLookup, "auto"); the reference is the lookup over the whole table's nodes
    # at the directions of each pair and stage angle, computed here one pair at a time.
    table = _lobe_table()
    light, sensor = np.array([_dir(45, 0), _dir(60, 90), _dir(20, 200)]), np.array(
        [_dir(45, 180), _dir(30, 300), _dir(70, 10)])
    s = CalibratedScan(pairs=[("L1", "S1"), ("L2", "S1"), ("L3", "S2")], light_dirs=light,
                       sensor_dirs=sensor, stage_angles_deg=np.array([0.0, 120.0]),
                       values=np.ones((3, 2, 3)), channels=("R", "G", "B"),
                       calibration={"pairs": []})
    res = read_result(write_result(tmp_path / "lobe.h5", job_id=5, specimen="lobe",
                                   kind="uniform", readings=[], samples=s, table=table))
    assert res.table is not None
    whole = render.TableLookup(res.table, nodes="table")  # as stored (float32)
    fit = fit_curves(res, step_deg=3.0)
    alphas = np.deg2rad(fit["curve_deg"])
    for q, pair in enumerate(fit["pairs"]):
        wi = geo.lab_to_specimen(np.broadcast_to(light[q], (alphas.size, 3)), alphas)
        wo = geo.lab_to_specimen(np.broadcast_to(sensor[q], (alphas.size, 3)), alphas)
        assert pair["curve"] == whole.eval(wi, wo).mean(axis=1).tolist()
    polar = polar_curves(res, 40.0, 30.0)["reconstruction"]
    ti, pi_ = np.deg2rad(40.0), np.deg2rad(30.0)
    a = np.deg2rad(np.arange(-89.0, 90.0))
    wi = np.array([np.sin(ti) * np.cos(pi_), np.sin(ti) * np.sin(pi_), np.cos(ti)])
    wo = np.stack([-np.sin(a) * np.cos(pi_), -np.sin(a) * np.sin(pi_), np.cos(a)], axis=1)
    ref = whole.eval(np.broadcast_to(wi, wo.shape), wo)
    for c, ch in enumerate("RGB"):
        assert polar["in_plane"][ch] == ref[:, c].tolist()
    assert max(polar["in_plane"]["R"]) > 10 * min(polar["in_plane"]["R"])  # a lobe, not flat


def test_no_truth_on_an_uncalibrated_result(tmp_path: Path) -> None:
    res = read_result(_result(tmp_path, _table(), calibrated=False))
    assert true_material(res) is None
    assert polar_curves(res, 30.0, 0.0)["truth"] is None
    assert fit_curves(res)["units"] == "sensor units (uncalibrated)"


def test_a_calibration_result_has_no_curves_and_no_picture(tmp_path: Path) -> None:
    path = _result(tmp_path, None, kind="calibration")
    res = read_result(path)
    for call in (lambda: fit_curves(res), lambda: polar_curves(res, 30, 0)):
        with pytest.raises(FigureError, match="no reconstructed BRDF"):
            call()
    with pytest.raises(FigureError, match=r"holds no reconstructed BRDF .* a calibration "
                                          r"result\); render a scan's result"):
        load_input(path)
    with pytest.raises(FigureError, match="nothing to render"):
        render_inputs([])


def test_the_rows_of_a_figure(tmp_path: Path, npz: Path) -> None:
    path = _result(tmp_path, _table())
    rows = load_input(path)
    assert [label for label, _ in rows] == ["truth: paper", "job 4: card (reconstruction)"]
    assert [label for label, _ in load_input(path, "mine", with_truth=False)] == [
        "mine (reconstruction)"]
    assert [label for label, _ in load_input(npz)] == ["t.npz: flat"]


def test_fit_curves_of_a_spectral_result_name_the_bands_in_a_line(tmp_path: Path) -> None:
    """The page's readings plot puts ``channels`` beside its y axis. A 31-band spectrometer
    scan's was "mean of 400nm, 410nm, ..., 700nm", 31 names, far past the axis (cut off on
    the page); a few channels are still named one by one."""
    names = [f"{w}nm" for w in range(400, 701, 10)]
    table = from_function(lambda i, o: np.full((i.shape[0], len(names)), 0.1), names, "paint")
    cal = {"pairs": [{"light": "L1", "sensor": "S1", "factor": [1.0] * len(names)}]}
    s = CalibratedScan(pairs=[("L1", "S1")], light_dirs=np.array([_dir(45, 0)]),
                       sensor_dirs=np.array([_dir(30, 180)]), stage_angles_deg=np.zeros(1),
                       values=np.full((1, 1, len(names)), 0.1), channels=tuple(names),
                       calibration=cal)
    path = write_result(tmp_path / "s.h5", job_id=5, specimen="paint", kind="uniform",
                        readings=[], samples=s, table=table)
    fit = fit_curves(read_result(path), step_deg=90.0)
    assert fit["channels"] == "mean of 31 channels, 400nm to 700nm"
