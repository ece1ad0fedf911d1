"""The pictures' lookup (monotone cubic in log along th, linear in log elsewhere) against
formulas: slopes of Fritsch & Butland, exact on an exponential fall-off, no overshoot, monotone
data stay monotone, a narrow lobe followed closer than by the multilinear lookup."""

from __future__ import annotations

import numpy as np
import pytest

from gonio.brdf.pictures.render import RenderError, TableLookup
from gonio.brdf.tables import geometry as geo
from gonio.brdf.tables import interpolation as interp
from gonio.brdf.tables.table import BRDFTable


def _table_of_th(f_th: np.ndarray) -> BRDFTable:
    """A one-channel table whose value depends on the th node only (f_th: (18,))."""
    v = np.broadcast_to(f_th[None, None, :, None, None], (1, *geo.TABLE_SHAPE)).copy()
    return BRDFTable(v, ("Y",), "th-only")


def _queries(rng: np.random.Generator, n: int, th_max_deg: float = 45.0
             ) -> tuple[np.ndarray, ...]:
    """Random half/difference angles inside the region where every neighbour is valid."""
    th = np.deg2rad(rng.uniform(0.0, th_max_deg, n))
    td = np.deg2rad(rng.uniform(0.0, 40.0, n))
    return th, rng.uniform(0, 2 * np.pi, n), td, rng.uniform(0, np.pi, n)


def test_slopes_are_the_harmonic_mean_of_the_secants_and_zero_at_an_extremum() -> None:
    # Along th at one (ph, td, pd): 1, 2, 4, 3, then 3 everywhere; secants 1, 2, -1, 0, ...
    f_th = np.array([1.0, 2.0, 4.0, 3.0] + [3.0] * (geo.N_TH - 4))
    logs = np.broadcast_to(f_th[None, :, None, None], geo.TABLE_SHAPE).reshape(-1, 1)
    logs = np.ascontiguousarray(logs)
    valid = np.ones(logs.shape[0], dtype=bool)
    s = interp.node_slopes(logs, valid).reshape(*geo.TABLE_SHAPE)[0, :5, 0, 0]
    assert s[0] == 1.0  # end of the axis: the secant to the one neighbour
    assert s[1] == pytest.approx(2.0 / (1.0 / 1.0 + 1.0 / 2.0))  # 4/3
    assert s[2] == 0.0  # secants 2 and -1 differ in sign: a local maximum
    assert s[3] == 0.0 and s[4] == 0.0  # a flat secant beside it: no slope
    # Beside an invalid node: the secant to the valid side.
    valid = valid.reshape(geo.TABLE_SHAPE).copy()
    valid[:, 3] = False
    s = interp.node_slopes(logs, valid.ravel()).reshape(*geo.TABLE_SHAPE)[0, :3, 0, 0]
    assert s[2] == 2.0


def test_hermite_meets_its_nodes_and_slopes() -> None:
    y0, y1, s0, s1 = (np.array([v]) for v in (1.0, 3.0, 0.5, -2.0))
    h = 1e-6
    assert interp.hermite(y0, y1, s0, s1, np.array([0.0]))[0] == pytest.approx(1.0)
    assert interp.hermite(y0, y1, s0, s1, np.array([1.0]))[0] == pytest.approx(3.0)
    d0 = (interp.hermite(y0, y1, s0, s1, np.array([h])) - y0) / h
    d1 = (y1 - interp.hermite(y0, y1, s0, s1, np.array([1.0 - h]))) / h
    assert d0[0] == pytest.approx(0.5, abs=1e-4) and d1[0] == pytest.approx(-2.0, abs=1e-4)


def test_an_exponential_fall_off_in_th_is_followed_exactly() -> None:
    # ln f linear in th: equal secants, so the monotone slopes are that line's slope and the
    # cubic is the line itself. eps = 1e-3 x mean shifts each node's log by at most eps / f,
    # and a neighbour is at least exp(k) f, so the value is off by at most about 3 eps.
    k = -0.6  # per 5 degree step
    f_th = 10.0 * np.exp(k * np.arange(geo.N_TH))
    table = _table_of_th(f_th)
    rng = np.random.default_rng(1)
    th, ph, td, pd = _queries(rng, 2000)
    truth = 10.0 * np.exp(k * th / geo.STEP)
    got = TableLookup(table).eval_half_diff(th, ph, td, pd)[:, 0]
    eps = interp.LOG_EPS * float(np.nanmean(np.asarray(table.values)))
    np.testing.assert_allclose(got, truth, rtol=1e-9, atol=4 * eps)
    # The multilinear lookup cuts the same curve with chords: far outside that tolerance.
    lin = TableLookup(table, "multilinear").eval_half_diff(th, ph, td, pd)[:, 0]
    assert np.max(np.abs(lin - truth)) > 20 * 4 * eps


def test_every_value_lies_between_its_neighbours() -> None:
    rng = np.random.default_rng(2)
    v = np.exp(rng.normal(0.0, 2.0, size=(2, *geo.TABLE_SHAPE)))
    table = BRDFTable(v, ("R", "G"), "random")
    th, ph, td, pd = _queries(rng, 3000)
    got = TableLookup(table).eval_half_diff(th, ph, td, pd)
    # The 16 neighbouring nodes, found here from the grid's definition (math.md 3).
    i_th = np.floor(th / geo.STEP).astype(int)
    i_td = np.floor(td / geo.STEP).astype(int)
    i_ph = np.floor(ph / geo.STEP).astype(int)
    i_pd = np.floor(pd / geo.STEP).astype(int)
    corners = np.stack([
        v[:, (i_ph + a) % geo.N_PH, i_th + b, i_td + c, (i_pd + d) % geo.N_PD]
        for a in (0, 1) for b in (0, 1) for c in (0, 1) for d in (0, 1)])  # (16, C, N)
    lo, hi = corners.min(axis=0).T, corners.max(axis=0).T
    assert np.all(got >= lo * (1 - 1e-9)) and np.all(got <= hi * (1 + 1e-9))


def test_monotone_data_give_a_monotone_lookup() -> None:
    # Rising in th with uneven steps (a plateau, a jump): the cubic must not overshoot.
    steps = np.array([0, 0.1, 0.1, 0, 0, 5.0, 0.2, 0.2, 3.0, 0, 0, 0, 0.5, 0.5, 9, 0, 1, 1])
    table = _table_of_th(0.5 + np.cumsum(steps))
    th = np.deg2rad(np.linspace(0.0, 85.0, 3401))
    n = th.size
    got = TableLookup(table).eval_half_diff(th, np.full(n, 0.3), np.full(n, 0.0),
                                            np.full(n, 0.2))[:, 0]
    assert np.all(np.diff(got) >= -1e-9 * got[1:])


def test_a_narrow_lobe_is_followed_closer_than_by_the_multilinear_lookup() -> None:
    # A Gaussian highlight of 4 degrees over a diffuse body, against its formula between
    # the nodes.
    sigma = np.deg2rad(4.0)

    def lobe(th: np.ndarray) -> np.ndarray:
        return 0.2 + 50.0 * np.exp(-0.5 * (th / sigma) ** 2)

    table = _table_of_th(lobe(geo.TH_GRID))
    th = np.deg2rad(np.linspace(0.0, 30.0, 601))
    args = (th, np.zeros_like(th), np.full_like(th, 0.1), np.zeros_like(th))
    err = {how: np.mean(np.abs(np.log(TableLookup(table, how).eval_half_diff(*args)[:, 0]
                                      / lobe(th))))
           for how in interp.INTERPOLATIONS}
    assert err["log-pchip"] < 0.5 * err["multilinear"]


@pytest.mark.parametrize("how", interp.INTERPOLATIONS)
def test_a_constant_table_stays_constant_up_to_the_horizon(how: interp.Interpolation) -> None:
    # Near the horizon some neighbours are invalid; their weights are left out, so a
    # constant comes back unchanged wherever any neighbour is valid.
    table = BRDFTable(np.full((1, *geo.TABLE_SHAPE), 0.7), ("Y",), "constant")
    rng = np.random.default_rng(4)
    th = np.deg2rad(rng.uniform(0, 89, 5000))
    td = np.deg2rad(rng.uniform(0, 89, 5000))
    got = TableLookup(table, how).eval_half_diff(th, rng.uniform(0, 7, 5000), td,
                                                 rng.uniform(0, 4, 5000))[:, 0]
    some = got > 0
    assert some.mean() > 0.5
    np.testing.assert_allclose(got[some], 0.7, rtol=1e-6)  # the lookup stores float32


def test_an_unknown_interpolation_is_refused_with_the_choices() -> None:
    table = _table_of_th(np.ones(geo.N_TH))
    with pytest.raises(RenderError, match="log-pchip, multilinear"):
        TableLookup(table, "cubic")  # type: ignore[arg-type]


def test_packed_nodes_hold_each_cell_value_beside_its_slope() -> None:
    logs = np.arange(12.0).reshape(4, 3)
    slopes = -logs
    nodes = interp.pack_nodes(logs, slopes)
    assert nodes.shape == (4, 6) and nodes.flags.c_contiguous
    np.testing.assert_array_equal(nodes[2], [6.0, 7.0, 8.0, -6.0, -7.0, -8.0])


def test_table_nodes_are_the_clamped_logs_beside_their_slopes() -> None:
    from gonio.brdf.tables import geometry as geo
    from gonio.brdf.tables.interpolation import LOG_EPS, node_slopes, table_nodes

    rng = np.random.default_rng(5)
    values = rng.uniform(-0.1, 3.0, size=(2, *geo.TABLE_SHAPE))
    values[:, :, 4, 2, 7] = np.nan  # an invalid cell in every ph slice
    values[1, 3, 5, 6, 8] = np.nan  # invalid in one channel: the cell is invalid
    nodes, ok, eps = table_nodes(values)
    flat = np.moveaxis(values, 0, -1).reshape(-1, 2)
    assert np.array_equal(ok, np.isfinite(flat).all(axis=1))
    clamped = np.clip(flat[ok], 0.0, None)
    assert eps == pytest.approx(LOG_EPS * clamped.mean())
    logs = np.zeros_like(flat)
    logs[ok] = np.log(clamped + eps)
    logs[~ok] = np.log(eps)
    assert np.allclose(nodes[:, :2], logs, rtol=0, atol=1e-12)
    assert np.array_equal(nodes[:, 2:], node_slopes(nodes[:, :2], ok))
