"""The unread-lobe witness of ``bench/bench_ma98metal.py`` (docs/science.md 7.1.1.3)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from gonio.brdf.tables import geometry as geo
from tests.unit.bench_import import import_bench

bm = import_bench("bench_ma98metal")

# A layout reaching theta_d 30 deg at most (radians: theta_h, theta_d, phi_d).
CELLS = np.deg2rad(np.array([[10.0, 30.0, 0.0], [20.0, 10.0, 90.0]]))


def _table(values: np.ndarray) -> SimpleNamespace:
    """A table of one channel whose (18, 18, 36) slice ``values`` is the same at every ph."""
    return SimpleNamespace(values=np.broadcast_to(values, (1, geo.N_PH, *values.shape)))


def _lobe_at(td_max_deg: float) -> np.ndarray:
    """A Lambertian 0.2 1/sr body with a lobe of 5 1/sr at theta_h < 15 deg, for every
    theta_d up to ``td_max_deg``."""
    th, td, _pd = geo.grid_angles()
    f = np.full(th.shape, 0.2)
    f[(th < np.deg2rad(15.0)) & (td < np.deg2rad(td_max_deg))] = 5.0
    return f


def test_a_lambertian_table_has_no_unread_lobe() -> None:
    flat = _table(np.full((18, 18, 36), 0.3))
    assert bm.unread_lobe(flat, CELLS) == pytest.approx(0.0, abs=1e-12)


def test_a_lobe_only_where_the_layout_reads_is_not_counted() -> None:
    # theta_d up to 32.5 deg: the read ones and the half step beyond the layout's 30 deg.
    assert bm.unread_lobe(_table(_lobe_at(33.0)), CELLS) == pytest.approx(0.0, abs=1e-12)


def test_a_lobe_carried_into_unread_theta_d_is_counted_and_grows_with_it() -> None:
    small = bm.unread_lobe(_table(_lobe_at(60.0)), CELLS)
    large = bm.unread_lobe(_table(_lobe_at(90.0)), CELLS)
    assert 0.0 < small < large
    # The layout reading theta_d up to 85 deg leaves only the last grid row unread.
    wide = np.deg2rad(np.array([[10.0, 85.0, 0.0]]))
    assert bm.unread_lobe(_table(_lobe_at(90.0)), wide) < small
