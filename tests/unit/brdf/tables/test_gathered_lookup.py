"""The log-pchip lookup with its nodes computed only where its points read ("gathered")
against the same lookup over the whole table's nodes (the reference implementation): equal
bit for bit on tables with invalid cells at grazing, with many channels and with zeros, at
random direction pairs and at the ends of the ``th`` axis; and far fewer nodes computed."""

from __future__ import annotations

import numpy as np
import pytest

from gonio.brdf.pictures.render import GATHER_SHARE, RenderError, TableLookup
from gonio.brdf.tables import geometry as geo
from gonio.brdf.tables import interpolation as interp
from gonio.brdf.tables.table import VALID_MASK, BRDFTable

N_CELLS = int(np.prod(geo.TABLE_SHAPE))


def _random_table(n_channels: int, seed: int, zeros: float = 0.0, holes: float = 0.0
                  ) -> BRDFTable:
    """Log-normal values over 6 decades, NaN where the grid has no valid cell (grazing), a
    share ``zeros`` of exact zeros (a polished metal's tails) and a share ``holes`` of NaN
    cells anywhere (so a valid node meets an invalid one on either side along ``th``)."""
    rng = np.random.default_rng(seed)
    v = np.exp(rng.normal(0.0, 3.0, size=(n_channels, *geo.TABLE_SHAPE))).astype(np.float32)
    v[:, rng.random(geo.TABLE_SHAPE) < zeros] = 0.0
    v[:, rng.random(geo.TABLE_SHAPE) < holes] = np.nan
    v[:, :, ~VALID_MASK] = np.nan
    return BRDFTable(v, tuple(f"c{k}" for k in range(n_channels)), f"random-{n_channels}")


def _hemisphere(rng: np.random.Generator, n: int) -> np.ndarray:
    theta = np.arccos(rng.uniform(0.0, 1.0, n))
    phi = rng.uniform(0.0, 2 * np.pi, n)
    return np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi),
                     np.cos(theta)], axis=1)


def _both(table: BRDFTable) -> tuple[TableLookup, TableLookup]:
    return TableLookup(table, nodes="table"), TableLookup(table, nodes="gathered")


def test_the_table_has_invalid_cells_near_grazing() -> None:
    # What the tests below rely on: NaN cells beside valid ones, so slopes and weights meet
    # invalid neighbours.
    v = np.asarray(_random_table(1, 0).values)
    assert np.isnan(v).any() and np.isfinite(v).any()


@pytest.mark.parametrize(("n_channels", "zeros", "holes"),
                         [(1, 0.0, 0.0), (3, 0.3, 0.2), (31, 0.0, 0.05)])
def test_gathered_nodes_give_the_whole_tables_lookup_bit_for_bit(n_channels: int, zeros: float,
                                                                  holes: float) -> None:
    table = _random_table(n_channels, seed=n_channels, zeros=zeros, holes=holes)
    whole, gathered = _both(table)
    rng = np.random.default_rng(10 + n_channels)
    # Pairs over the whole hemisphere, with many near grazing where invalid cells are read.
    wi, wo = _hemisphere(rng, 600), _hemisphere(rng, 600)
    for w in (wi[400:], wo[400:]):  # both grazing: td near 90 degrees
        w[:, 2] = rng.uniform(1e-4, 0.1, 200)
        w /= np.linalg.norm(w, axis=1, keepdims=True)
    ref = whole.eval(wi, wo)
    got = gathered.eval(wi, wo)
    assert got.shape == (600, n_channels)
    assert np.array_equal(got, ref)
    # The grazing pairs do reach cells whose neighbours are invalid (else (a) tests nothing).
    _th, _ph, td, _pd = geo.directions_to_half_diff(wi[400:], wo[400:])
    assert np.any(np.rad2deg(td) > geo.STEP_DEG * (geo.N_TD - 2))


def test_bit_for_bit_at_th_zero_and_at_the_last_th_node() -> None:
    table = _random_table(3, seed=7, zeros=0.1, holes=0.1)
    whole, gathered = _both(table)
    rng = np.random.default_rng(8)
    last = (geo.N_TH - 1) * geo.STEP  # 85 degrees: the last node, where th's slope is a secant
    th = np.concatenate([np.zeros(300), np.full(300, last), np.full(100, np.pi / 2),
                         rng.uniform(last - geo.STEP, last, 100), rng.uniform(0, geo.STEP, 100)])
    n = th.size
    args = (th, rng.uniform(-1.0, 7.5, n), rng.uniform(0.0, np.pi / 2, n),
            rng.uniform(-1.0, 4.0, n))
    ref = whole.eval_half_diff(*args, empty=np.nan)
    got = gathered.eval_half_diff(*args, empty=np.nan)
    # array_equal treats NaN as unequal: compare where each is NaN, then the numbers.
    assert np.array_equal(np.isnan(got), np.isnan(ref)) and np.isfinite(ref).any()
    assert np.array_equal(np.nan_to_num(got, nan=-1.0), np.nan_to_num(ref, nan=-1.0))


def test_gathered_slopes_are_the_whole_tables_slopes_at_those_cells() -> None:
    table = _random_table(2, seed=3, zeros=0.2, holes=0.2)
    v = np.asarray(table.values)
    flat = np.moveaxis(v, 0, -1).reshape(-1, 2)
    ok: np.ndarray = np.asarray(np.isfinite(flat).all(axis=1))
    values = np.where(ok[:, None], flat, 0.0)
    eps = interp.log_offset(values, ok)
    logs = interp.node_logs(values, eps)
    whole = interp.pack_nodes(logs, interp.node_slopes(logs, ok))
    rng = np.random.default_rng(5)
    s_th = geo.N_TD * geo.N_PD
    # Cells at both ends of th and in between, with their th neighbours not all asked for.
    cells = np.unique(np.concatenate([rng.integers(0, N_CELLS, 500),
                                      rng.integers(0, N_CELLS // s_th, 50) * s_th,
                                      rng.integers(1, N_CELLS // s_th + 1, 50) * s_th - 1]))
    nodes, computed = interp.gathered_nodes(values, ok, eps, cells)
    assert np.array_equal(nodes, whole[cells])
    assert cells.size <= computed <= 3 * cells.size


def test_the_gathered_cells_are_the_lookups_sixteen_neighbours() -> None:
    # One point inside the grid: its 16 neighbours from the grid's definition (math.md 3).
    th, ph, td, pd = (np.deg2rad(np.array([a])) for a in (12.0, 102.0, 33.0, 7.0))
    cells = interp.gathered_cells(th, ph, td, pd)
    want = sorted(np.ravel_multi_index((p, t, d, q), geo.TABLE_SHAPE)
                  for p in (20, 21) for t in (2, 3) for d in (6, 7) for q in (1, 2))
    assert cells.tolist() == want


def test_a_few_points_compute_far_fewer_nodes_than_the_table_holds() -> None:
    table = _random_table(3, seed=11)
    rng = np.random.default_rng(12)
    wi, wo = _hemisphere(rng, 1000), _hemisphere(rng, 1000)
    auto = TableLookup(table)  # "auto": gathers for this few
    auto.eval(wi, wo)
    # At most 32 cells' logs a point (16 neighbours and their th neighbours).
    assert 0 < auto.nodes_computed <= 32 * 1000 < N_CELLS // 20
    whole = TableLookup(table, nodes="table")
    whole.eval(wi, wo)
    assert whole.nodes_computed == N_CELLS


def test_auto_turns_to_the_whole_table_for_many_points_and_keeps_it() -> None:
    table = _random_table(1, seed=13)
    look = TableLookup(table)
    rng = np.random.default_rng(14)
    many = int(GATHER_SHARE * N_CELLS / 32) + 1
    args = (rng.uniform(0, np.pi / 2, many), rng.uniform(0, 7, many),
            rng.uniform(0, np.pi / 2, many), rng.uniform(0, 4, many))
    look.eval_half_diff(*args)
    assert look.nodes_computed == N_CELLS
    th, ph, td, pd = args
    look.eval_half_diff(th[:10], ph[:10], td[:10], pd[:10])  # few now read the whole table's
    assert look.nodes_computed == N_CELLS


def test_an_unknown_node_choice_is_refused_with_the_choices() -> None:
    with pytest.raises(RenderError, match="use one of auto, table, gathered"):
        TableLookup(_random_table(1, seed=1), nodes="some")  # type: ignore[arg-type]
