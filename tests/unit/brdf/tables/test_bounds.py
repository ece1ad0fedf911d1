"""Physical bounds of a table (issue 23 item 4): directional albedo and peak ratio."""

from __future__ import annotations

import math

import numpy as np
import pytest

from gonio.brdf.models import analytic as bm
from gonio.brdf.tables import bounds
from gonio.brdf.tables.table import BRDFTable


def _lambert(albedo: float) -> BRDFTable:
    """A Lambertian table of any albedo (Lambert itself refuses albedo above 1)."""
    t = bm.tabulate(bm.Lambert(0.5), np.float64)
    return BRDFTable(np.asarray(t.values) * (albedo / 0.5), t.channels, f"lambert {albedo}")


def test_a_lambertian_of_albedo_one_half_has_directional_albedo_one_half() -> None:
    # integral of (a / pi) cos(theta_o) dw over the hemisphere is a, at every incidence.
    alb = bounds.directional_albedo(_lambert(0.5), exclude_deg=0.0)
    assert alb.shape == (len(bounds.INCIDENCE_DEG), len(bounds.INCIDENCE_AZIMUTH_DEG), 3)
    np.testing.assert_allclose(alb, 0.5, rtol=2e-3)
    # Default: the cone of half vectors within 7.5 degrees of the normal is left out; at normal
    # incidence that is the cone of outgoing directions within 15 degrees, which holds
    # sin^2(15 deg) of the cosine-weighted hemisphere.
    off = bounds.directional_albedo(_lambert(0.5))
    np.testing.assert_allclose(off[0], 0.5 * (1 - math.sin(math.radians(15)) ** 2), rtol=3e-3)
    assert np.all(off <= 0.5 * (1 + 2e-3))
    check = bounds.bounds_check(_lambert(0.5), readings=[0.5 / math.pi])
    assert check.ok and check.message() is None
    assert check.worst_albedo == pytest.approx(0.5, rel=0.02)
    assert check.peak_ratio == pytest.approx(1.0, rel=1e-6)  # the table is flat at the reading


def test_a_lambertian_scaled_above_one_is_out_of_bounds_and_says_why() -> None:
    check = bounds.bounds_check(_lambert(2.0), readings=[2.0 / math.pi])
    assert check.worst_albedo == pytest.approx(2.0, rel=0.02)
    assert check.albedo_exceeded and not check.peak_exceeded and not check.ok
    msg = check.message()
    # 2 x 0.9944: at 75 degrees the mirror cone leaves out 0.56 % of a Lambertian.
    assert msg is not None and "albedo (off the mirror direction) reaches 1.99" in msg
    d = check.as_dict()
    assert d["ok"] is False and d["albedo_limit"] == bounds.ALBEDO_LIMIT


def test_a_narrow_mirror_lobe_tabulated_exactly_stays_in_bounds() -> None:
    """A polished metal's true table is no reconstruction error: its lobe, narrower than the
    grid, must not read as reflecting more than falls on it."""
    ggx = bm.GGX(0.01, 0.01, fresnel=bm.SchlickFresnel((1.0, 1.0, 1.0)))
    table = bm.tabulate(ggx, np.float64)
    assert bounds.directional_albedo(table, exclude_deg=0.0).max() > 10  # the node artefact
    check = bounds.bounds_check(table, readings=[float(np.nanmax(np.asarray(table.values)))])
    assert check.ok


def test_a_table_far_above_every_reading_is_out_of_bounds_even_in_sensor_units() -> None:
    # One cell blown up to 1e13 while the readings stay below 0.75: the case.
    v = np.asarray(_lambert(0.5).values).copy()
    v[:, 3, 4, 5, 6] = 2.3e13
    table = BRDFTable(v, ("R", "G", "B"), "blown up")
    check = bounds.bounds_check(table, readings=np.array([[0.1, 0.75], [np.nan, 0.2]]),
                                calibrated=False)
    assert math.isnan(check.worst_albedo)  # not compared with 1 in sensor units
    # The bound compares projected values, f cos ti cos to; readings of unknown geometry count
    # as they are.
    w = bounds.projection_weight()[4, 5, 6]
    assert check.peak_ratio == pytest.approx(2.3e13 * w / 0.75, rel=1e-6)
    assert check.peak_exceeded and not check.ok
    assert "times the largest reading" in (check.message() or "")


def test_the_error_above_the_peak_bound_is_a_lower_bound_for_any_truth_within_it() -> None:
    """``peak_excess_log_rmse`` is the log_rmse of the table against itself capped at
    PEAK_RATIO_LIMIT x the largest reading over each cell's cos ti cos to; any truth at or below
    the cap where the table is above it is at least that far from the table (ln(1 + f cos ti)
    grows with f)."""
    from gonio.brdf.tables import geometry as geo
    from gonio.brdf.tables import metrics

    base = np.asarray(_lambert(0.5).values)
    v = base.copy()
    cells = [(3, 4, 5, 6), (10, 2, 3, 4), (40, 6, 1, 20)]
    for ph, th, td, pd in cells:
        v[:, ph, th, td, pd] = [1e6, 3e5, 2e7]
    table = BRDFTable(v, ("R", "G", "B"), "blown up")
    readings = np.array([0.1, 0.75, np.nan])
    ci, co = geo.cell_cosines(*geo.grid_angles())
    with np.errstate(divide="ignore"):
        cap = np.where(geo.valid_mask(), bounds.PEAK_RATIO_LIMIT * 0.75 / (ci * co), np.inf)
    excess = bounds.peak_excess_log_rmse(table, readings)
    assert excess > 0
    # Equality: the truth equals the cap where the table is above it, the table elsewhere.
    at_cap = BRDFTable(np.minimum(v, cap), table.channels, "at the cap")
    assert excess == pytest.approx(metrics.log_rmse(table, at_cap), rel=1e-12)
    # Any truth within the bound is at least that far from the table.
    rng = np.random.default_rng(5)
    for _ in range(5):
        t = base * rng.uniform(0.5, 2.0, base.shape)
        for ph, th, td, pd in cells:
            t[:, ph, th, td, pd] = rng.uniform(0.0, cap[th, td, pd], 3)
        truth = BRDFTable(t, table.channels, "a truth within the bound")
        assert metrics.log_rmse(table, truth) >= excess
    # Within the bound: nothing; no positive reading: undefined.
    assert bounds.peak_excess_log_rmse(_lambert(0.5), [0.2]) == 0.0
    assert math.isnan(bounds.peak_excess_log_rmse(table, [0.0, np.nan]))
    check = bounds.bounds_check(table, readings, calibrated=False)
    assert check.peak_excess_log_rmse == pytest.approx(excess)
    assert check.as_dict()["peak_excess_log_rmse"] == pytest.approx(excess)
    assert f"alone is {excess:.3g} in log_rmse, so predicted_log_rmse is at least that" in (
        check.message() or "")


def _rig_scan(model: object, rotations: int = 8) -> tuple[np.ndarray, np.ndarray]:
    """(pair cells, exact readings (12, rotations, C)) of ``model`` on the default simulated
    rig's twelve pairs (3 lamps x 4 sensors), stage angles over half a turn."""
    from gonio.brdf.reconstruction.reconstruct import pair_cells
    from gonio.brdf.reconstruction.samples import (
        NoiseModel,
        simulate_samples,
        uniform_stage_angles,
    )
    from gonio.sim.rig import DEFAULT_LIGHTS, DEFAULT_SENSORS

    def direction(theta_deg: float, phi_deg: float) -> list[float]:
        t, p = math.radians(theta_deg), math.radians(phi_deg)
        return [math.sin(t) * math.cos(p), math.sin(t) * math.sin(p), math.cos(t)]

    lights = np.array([direction(*d) for d in DEFAULT_LIGHTS for _ in DEFAULT_SENSORS])
    sensors = np.array([direction(*d) for _ in DEFAULT_LIGHTS for d in DEFAULT_SENSORS])
    cells, ph = pair_cells(lights, sensors)
    vals = simulate_samples(model, cells, ph, uniform_stage_angles(rotations, span=math.pi),
                            noise=NoiseModel(0.0, 0.0))
    return cells, vals


def _analytic_albedo(model: object, theta_i_deg: float) -> np.ndarray:
    """(C,) directional albedo of ``model`` at incidence ``theta_i_deg`` (azimuth 0), midpoint
    rule on a 0.25 x 1 degree grid of the outgoing hemisphere, straight from the model: no
    table, no cone left out."""
    n_t, n_p = 360, 360
    dth, dph = 0.5 * math.pi / n_t, 2 * math.pi / n_p
    tt, pp = np.meshgrid((np.arange(n_t) + 0.5) * dth, (np.arange(n_p) + 0.5) * dph,
                         indexing="ij")
    wo = np.stack([np.sin(tt) * np.cos(pp), np.sin(tt) * np.sin(pp), np.cos(tt)], -1)
    ti = math.radians(theta_i_deg)
    wi = np.broadcast_to([math.sin(ti), 0.0, math.cos(ti)], wo.shape)
    f = np.asarray(model.eval(wi.reshape(-1, 3), wo.reshape(-1, 3)))  # type: ignore[attr-defined]
    w = (np.cos(tt) * np.sin(tt) * dth * dph).reshape(-1)
    return np.einsum("nc,n->c", f, w)


def test_a_plain_solid_paints_exact_table_is_within_bounds_on_the_simulated_rig() -> None:
    """sim's ``solid-red-paint`` (a red Lambertian under a clear coat of GGX alpha 0.06) is a
    physical material: the model itself reflects less than falls on it. Its exact table,
    checked against the readings the default simulated rig takes of it, must not be called
    outside physical bounds. Its value peaks where light and view are both 85 degrees from the
    normal (the coat's D F G / (4 cos ti cos to)), about 4e3 times the largest reading, which
    the bound on the unprojected values flagged (science.md 7.5)."""
    from gonio.brdf.colour.spectral import SpectralBands
    from gonio.brdf.tables.table import from_function
    from gonio.sim.spectral import spectral_specimen

    # Three 10 nm bands (the 31-band spectrometer's at 450, 550 and 650 nm): the same paint,
    # a tenth of the table.
    spec = spectral_specimen("solid-red-paint", SpectralBands((450.0, 550.0, 650.0),
                                                              (10.0, 10.0, 10.0)))
    true_albedo = max(float(_analytic_albedo(spec, t).max()) for t in (0.0, 45.0, 75.0))
    assert 0.2 < true_albedo < 1.0  # energy conservation of the model, no table involved
    truth = from_function(spec.eval, spec.channels, "solid-red-paint")
    cells, vals = _rig_scan(spec)
    check = bounds.bounds_check(truth, vals, cells=cells)
    # What the old bound compared: the exact table's maximum is far above 1000 readings.
    assert check.table_max > bounds.PEAK_RATIO_LIMIT * check.reading_max
    assert check.ok, check.message()
    assert check.peak_ratio < 100  # projected, the coat's peak is tens of readings
    assert check.worst_albedo <= true_albedo  # the check integrates a lower bound of it
    assert bounds.peak_excess_log_rmse(truth, vals, cells) == 0.0
