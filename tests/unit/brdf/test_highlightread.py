"""Is the reconstruction's highlight read? (gonio.brdf.highlightread; issue 23 item 4.)

Synthetic tables whose answer is known by construction: a narrow lobe at the normal over a
dull body, read at its peak (no warning) or only far from it (warning)."""

from __future__ import annotations

import numpy as np
import pytest

from gonio.brdf.highlightread import EXCESS_LIMIT, TD_MAX_DEG, highlight_read
from gonio.brdf.tables import geometry as geo
from gonio.brdf.tables.table import BRDFTable

BODY, LOBE, WIDTH_DEG = 0.05, 40.0, 4.0


def lobe_value(th: np.ndarray) -> np.ndarray:
    """A narrow lobe at the normal (half vector ``th``, radians) over a dull body, 1/sr."""
    return BODY + LOBE * np.exp(-(np.rad2deg(th) / WIDTH_DEG) ** 2)


def lobe_table(channels: int = 3) -> BRDFTable:
    th, _td, _pd = geo.grid_angles()
    v = np.broadcast_to(lobe_value(th), (channels, geo.N_PH, *geo.SLICE_SHAPE)).copy()
    v[:, :, ~geo.valid_mask()] = np.nan
    return BRDFTable.trusted(v, ("R", "G", "B")[:channels], "lobe")


def readings(cells_deg: list[tuple[float, float, float]], r: int = 8
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(cells, ph_lab, stage angles, values) of exact readings of the lobe at ``cells_deg``
    (``th, td, pd`` degrees) and ``r`` stage angles over half a turn."""
    cells = np.deg2rad(np.asarray(cells_deg, dtype=float))
    ph_lab = np.zeros(len(cells))
    alpha = np.linspace(0.0, np.pi, r, endpoint=False)
    v = lobe_value(cells[:, 0])[:, None, None] * np.ones((1, r, 3))
    return cells, ph_lab, alpha, v


def test_a_reading_at_the_peak_reads_the_highlight() -> None:
    cells, ph, alpha, v = readings([(0.0, 10.0, 0.0), (30.0, 20.0, 90.0), (50.0, 40.0, 45.0)])
    hr = highlight_read(lobe_table(), cells, ph, alpha, v)
    assert hr.peak_th_deg == 0.0 and hr.peak_td_deg <= TD_MAX_DEG
    assert hr.nearest_deg == pytest.approx(0.0, abs=1e-6)
    # Both projected: the peak cell's cos ti cos to at most 1, the reading's at td 10 0.97.
    assert 0.9 < hr.excess < 1.1
    assert not hr.flagged and hr.message() is None


def test_readings_only_far_from_a_narrow_lobe_do_not_read_it() -> None:
    cells, ph, alpha, v = readings([(30.0, 20.0, 90.0), (50.0, 40.0, 45.0), (20.0, 60.0, 10.0)])
    hr = highlight_read(lobe_table(), cells, ph, alpha, v)
    assert hr.peak_th_deg == 0.0
    assert hr.nearest_deg == pytest.approx(20.0, abs=1e-6)  # the th = 20 pair's half vector
    assert hr.excess > 100 * EXCESS_LIMIT  # the lobe over the body, ~800 times
    assert hr.flagged
    text = hr.message()
    assert text is not None and text.startswith("the highlight is not read")
    assert "20.0 degrees away" in text and "prior's extrapolation" in text
    m = hr.as_metrics()
    assert m["highlight_excess"] == pytest.approx(hr.excess)
    assert m["highlight_nearest_deg"] == pytest.approx(20.0, abs=1e-6)


def test_a_reading_on_the_lobes_flank_is_judged_by_how_bright_it_is() -> None:
    # th = 2.5 degrees sees exp(-(2.5/4)^2) = 68 % of the lobe: read (excess about 1.5);
    # th = 5 sees 21 %: about 4.7 times below the peak, beyond the limit (3.4).
    near = highlight_read(lobe_table(), *readings([(2.5, 10.0, 0.0), (40.0, 30.0, 0.0)]))
    flank = highlight_read(lobe_table(), *readings([(5.0, 10.0, 0.0), (40.0, 30.0, 0.0)]))
    assert near.excess == pytest.approx(1.0 / np.exp(-(2.5 / 4) ** 2), rel=0.05)
    assert flank.excess == pytest.approx(1.0 / np.exp(-(5 / 4) ** 2), rel=0.05)
    assert not near.flagged and flank.flagged
    assert near.nearest_deg == pytest.approx(2.5, abs=1e-6)


def test_the_peak_is_looked_for_where_the_renderings_look() -> None:
    # A grazing spike at td = 80 degrees (where a measured material's rows often peak) beside
    # the lobe: ignored by default (td up to 45), found when every cell is searched.
    t = lobe_table()
    v = np.asarray(t.values).copy()
    i_td = round(80.0 / geo.STEP_DEG)
    v[:, :, 6, i_td, :] = 1.0e5
    spiked = BRDFTable.trusted(v, t.channels, "spiked")
    cells, ph, alpha, vals = readings([(0.0, 10.0, 0.0), (40.0, 30.0, 0.0)])
    assert highlight_read(spiked, cells, ph, alpha, vals).peak_td_deg == 0.0
    assert not highlight_read(spiked, cells, ph, alpha, vals).flagged
    every = highlight_read(spiked, cells, ph, alpha, vals, td_max_deg=None)
    assert every.peak_td_deg == 80.0 and every.flagged


def test_reconstruct_and_demo_print_the_same_sentence() -> None:
    # `gonio reconstruct` and `gonio demo` print what finishing records for a scan.
    from gonio.cli.brdf_commands import _highlight_warning

    far = readings([(30.0, 20.0, 90.0), (50.0, 40.0, 45.0)])
    at = readings([(0.0, 10.0, 0.0), (50.0, 40.0, 45.0)])
    assert _highlight_warning(lobe_table(), *far) == highlight_read(lobe_table(), *far).message()
    assert _highlight_warning(lobe_table(), *far) is not None
    assert _highlight_warning(lobe_table(), *at) is None
