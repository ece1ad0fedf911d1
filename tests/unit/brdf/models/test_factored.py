"""The factored BRDF of 000 (rho_d, rho_s, D, F, G) and its alternating least-squares fit."""

from __future__ import annotations

import numpy as np
import pytest

from gonio.brdf.models import analytic as bm
from gonio.brdf.models import factored as fa
from gonio.brdf.tables import geometry as geo
from gonio.brdf.tables.table import BRDFTable

# A material the factored model can hold almost exactly: Lambert + GGX with separable Smith
# masking (G(i) G(o)) and Schlick Fresnel of the light-microfacet angle (a function of td).
AX, AY, ANGLE = 0.12, 0.40, np.deg2rad(30.0)
ALBEDO = (0.30, 0.20, 0.10)


def _material() -> bm.BRDFModel:
    spec = bm.GGX(AX, AY, bm.SchlickFresnel((0.9, 0.7, 0.5)), "separable")
    return bm.LobeSum((bm.Lambert(ALBEDO), bm.Rotated(spec, ANGLE)))


@pytest.fixture(scope="module")
def table() -> BRDFTable:
    return bm.tabulate(_material(), dtype=np.float64)


@pytest.fixture(scope="module")
def fitted(table: BRDFTable) -> fa.FactoredBRDF:
    return fa.fit_factored(table, iterations=8)


def _true_ndf() -> np.ndarray:
    """The model's NDF on D's grid, from the GGX formula (independent of the fit)."""
    th, ph = np.meshgrid(geo.TH_GRID, geo.PH_GRID, indexing="ij")
    h = geo.spherical_to_direction(th.ravel(), ph.ravel())
    return bm.ggx_ndf(geo.rotate_z(h, -ANGLE), AX, AY).reshape(th.shape)


def test_d_peaks_where_the_ndf_does(fitted: fa.FactoredBRDF) -> None:
    true = _true_ndf()
    assert np.unravel_index(np.argmax(fitted.D), fitted.D.shape)[0] == 0  # at the normal
    # Off the normal an anisotropic lobe is highest along its rough axis: the fitted D's
    # ridge must run along the same azimuth (mod 180 deg) at every elevation.
    for i_th in (2, 4, 6, 8):
        got = np.rad2deg(geo.PH_GRID[np.argmax(fitted.D[i_th])])
        want = np.rad2deg(geo.PH_GRID[np.argmax(true[i_th])])
        diff = (got - want + 90.0) % 180.0 - 90.0
        assert abs(diff) <= 5.0, (i_th, got, want)
    # And its shape follows the NDF over four decades.
    keep = true > true.max() * 1e-4
    r = np.corrcoef(np.log(fitted.D[keep]), np.log(true[keep]))[0, 1]
    assert r > 0.97


def test_fit_recovers_diffuse_and_reports_table1_metrics(
    fitted: fa.FactoredBRDF, table: BRDFTable
) -> None:
    np.testing.assert_allclose(fitted.rho_d, ALBEDO, rtol=0.1)
    m = fitted.metrics
    assert {"rel_mse", "mape", "psnr", "log_rmse", "iterations", "seconds"} <= set(m)
    assert m["rel_mse"] < 0.05 and m["mape"] < 0.15 and m["psnr"] > 35
    # The reported numbers are the metrics of the model's own table against the input.
    from gonio.brdf.tables import metrics

    assert m["rel_mse"] == pytest.approx(metrics.rel_mse(fitted.to_table(), table))
    # Dynamic-range clamp: every factor's maximum is 1 and its minimum at least 1e-6.
    for f in (fitted.D, fitted.G, *fitted.F):
        assert f.max() == pytest.approx(1.0) and f.min() >= fa.DR_MIN


def test_eval_matches_the_table_at_cell_centres(fitted: fa.FactoredBRDF) -> None:
    th, td, pd = geo.grid_angles()
    mask = geo.valid_mask()
    k = 7
    wi, wo = geo.half_diff_to_directions(th[mask], geo.PH_GRID[k], td[mask], pd[mask])
    np.testing.assert_allclose(
        fitted.eval(wi, wo), fitted.to_table().values[:, k][:, mask].T, rtol=1e-9, atol=1e-12
    )
    assert (fitted.eval([[0, 0, 1.0]], [[1.0, 0, 0]]) == 0).all()  # view on the horizon


def test_save_load_round_trip(fitted: fa.FactoredBRDF, tmp_path) -> None:
    p = fitted.save(tmp_path / "f.npz", {"job": 3})
    back = fa.FactoredBRDF.load(p)
    for key in ("rho_d", "rho_s", "D", "F", "G"):
        np.testing.assert_array_equal(getattr(back, key), getattr(fitted, key))
    assert back.channels == fitted.channels and back.metrics["rel_mse"] == fitted.metrics["rel_mse"]
    with np.load(p) as z:  # readable without gonio
        assert str(z["format"]) == "gonio-factored" and z["D"].shape == (18, 72)


def test_bad_input_is_refused_with_a_reason(table: BRDFTable, tmp_path) -> None:
    with pytest.raises(fa.FactoredError, match="weighting"):
        fa.fit_factored(table, weighting="log")  # type: ignore[arg-type]
    with pytest.raises(fa.FactoredError, match="iterations"):
        fa.fit_factored(table, iterations=0)
    zero = BRDFTable(np.zeros((1, *geo.TABLE_SHAPE)), ("Y",), "black")
    with pytest.raises(fa.FactoredError, match="no positive"):
        fa.fit_factored(zero)
    table.save(tmp_path / "t.npz")
    with pytest.raises(fa.FactoredError, match="not a gonio factored BRDF file"):
        fa.FactoredBRDF.load(tmp_path / "t.npz")
    with pytest.raises(fa.FactoredError, match="shape"):
        fa.FactoredBRDF(np.zeros(3), np.ones(3), np.ones((18, 72)), np.ones((3, 18)),
                        np.ones((18, 72)), ("R", "G", "B"))


def test_d_peaks_where_the_ndf_does_on_a_library_metal() -> None:
    """A library brushed metal: correlated Smith masking and conductor Fresnel, which the
    factored model can only approximate; its D must still follow the GGX NDF."""
    from gonio.brdf.materials import library

    mat = library.get_material("brushed-metal-003")
    assert isinstance(mat, bm.Rotated) and isinstance(mat.model, bm.GGX)
    ggx = mat.model
    fit = fa.fit_factored(bm.tabulate(mat, dtype=np.float64), iterations=6)
    th, ph = np.meshgrid(geo.TH_GRID, geo.PH_GRID, indexing="ij")
    h = geo.spherical_to_direction(th.ravel(), ph.ravel())
    true = bm.ggx_ndf(geo.rotate_z(h, -mat.angle), ggx.alpha_x, ggx.alpha_y).reshape(th.shape)
    assert np.argmax(fit.D) // geo.N_PH == 0
    for i_th in (2, 4, 8):
        diff = (np.rad2deg(geo.PH_GRID[np.argmax(fit.D[i_th])] - geo.PH_GRID[np.argmax(true[i_th])])
                + 90.0) % 180.0 - 90.0
        assert abs(diff) <= 5.0
    assert fit.metrics["rel_mse"] < 0.1
