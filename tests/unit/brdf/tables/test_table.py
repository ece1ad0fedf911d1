"""BRDFTable: validation, files, lookup accuracy and periodic wrap."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from gonio.brdf.models import analytic as bm
from gonio.brdf.tables import geometry as geo
from gonio.brdf.tables.table import FORMAT_NAME, BRDFTable, TableError

DEG = np.pi / 180
SHAPE = (3, *geo.TABLE_SHAPE)
ANISO = bm.Rotated(
    bm.LobeSum((bm.Lambert((0.3, 0.2, 0.1)), bm.GGX(0.3, 0.6, bm.DielectricFresnel(1.5)))), 0.5
)


@pytest.fixture(scope="module")
def aniso_table() -> BRDFTable:
    return bm.tabulate(ANISO, dtype=np.float64)


def ramp_values() -> np.ndarray:
    """Values that differ in every cell (so an index mix-up cannot go unnoticed)."""
    return np.arange(np.prod(SHAPE), dtype=np.float64).reshape(SHAPE) + 1.0


@pytest.mark.parametrize(
    ("values", "kwargs", "message"),
    [
        (
            np.ones((3, 72, 18, 18)), {},
            r"shape \(3, 72, 18, 18\), expected \(C, 72, 18, 18, 36\)",
        ),
        (np.ones((3, 36, 18, 18, 36)), {}, r"expected \(C, 72, 18, 18, 36\)"),
        (np.ones(SHAPE), {"channels": ("R", "G")}, r"2 channel names for 3 channels"),
        (np.ones(SHAPE), {"wavelengths_nm": (500.0,)}, r"1 wavelengths for 3 channels"),
        (np.full(SHAPE, np.nan), {}, r"no finite value at any valid cell"),
        (np.full(SHAPE, -0.5), {}, r"negative BRDF values .*clamp them to 0"),
        (np.where(np.arange(36) == 3, np.inf, np.ones(SHAPE)), {}, r"infinite values"),
    ],
    ids=["ndim", "ph-count", "channels", "wavelengths", "all-nan", "negative", "inf"],
)
def test_bad_tables_are_refused(
    values: np.ndarray, kwargs: dict[str, Any], message: str
) -> None:
    args = {"channels": ("R", "G", "B"), "name": "t", **kwargs}
    with pytest.raises(TableError, match=message):
        BRDFTable(values, **args)


def test_invalid_cells_become_nan_and_table_is_read_only() -> None:
    t = BRDFTable(np.ones(SHAPE), ("R", "G", "B"))
    mask = geo.valid_mask()
    assert np.isnan(t.values[:, :, ~mask]).all() and (t.values[:, :, mask] == 1).all()
    with pytest.raises(ValueError, match="read-only"):
        t.values[0, 0, 0, 0, 0] = 2.0
    # NaN at some valid cells is allowed (unmeasured), as long as something is finite.
    v = np.ones(SHAPE)
    v[:, :5] = np.nan
    assert np.isnan(BRDFTable(v, ("R", "G", "B")).values[:, :5]).all()


def test_columns_are_slices_in_c_order() -> None:
    t = BRDFTable(ramp_values(), ("R", "G", "B"))
    cols = t.columns()
    assert cols.shape == (3 * 72, geo.N_ROWS)
    c, i_ph, i_th, i_td, i_pd = 2, 40, 3, 4, 5
    row = geo.flat_row(i_th, i_td, i_pd)
    assert cols[c * 72 + i_ph, row] == t.values[c, i_ph, i_th, i_td, i_pd]


def test_save_load_round_trip(tmp_path: Path, aniso_table: BRDFTable) -> None:
    t = BRDFTable(
        aniso_table.values.astype(np.float32), ("R", "G", "B"), "mat", (610.0, 550.0, 465.0),
        {"note": "x", "n": 3},
    )
    path = t.save(tmp_path / "mat.npz")
    back = BRDFTable.load(path)
    np.testing.assert_array_equal(back.values, t.values)
    assert back.values.dtype == np.float32
    assert back.channels == t.channels and back.name == "mat"
    assert back.wavelengths_nm == (610.0, 550.0, 465.0)
    assert back.provenance["note"] == "x" and back.provenance["file"] == str(path)
    assert not list(tmp_path.glob("*.part"))  # the atomic write leaves no temporary file
    no_wl = BRDFTable.load(BRDFTable(np.ones(SHAPE), ("R", "G", "B")).save(tmp_path / "a.npz"))
    assert no_wl.wavelengths_nm is None


def _write_npz(path: Path, **fields: object) -> Path:
    with open(path, "wb") as fh:
        np.savez(fh, **fields)  # type: ignore[arg-type]
    return path


def test_load_errors(tmp_path: Path) -> None:
    with pytest.raises(TableError, match=r"absent\.npz: no such table file"):
        BRDFTable.load(tmp_path / "absent.npz")
    corrupt = tmp_path / "corrupt.npz"
    corrupt.write_bytes(b"PK\x03\x04 this is not really a zip")
    with pytest.raises(TableError, match=r"corrupt\.npz: not a readable gonio table file"):
        BRDFTable.load(corrupt)
    other = _write_npz(tmp_path / "other.npz", x=np.ones(3))
    with pytest.raises(TableError, match=f"not a gonio table file .*{FORMAT_NAME}"):
        BRDFTable.load(other)
    future = _write_npz(tmp_path / "future.npz", format=np.array(FORMAT_NAME), version=np.array(99))
    with pytest.raises(TableError, match=r"format version 99; this gonio reads version 1"):
        BRDFTable.load(future)
    partial = _write_npz(
        tmp_path / "partial.npz", format=np.array(FORMAT_NAME), version=np.array(1),
        values=np.ones(SHAPE),
    )
    with pytest.raises(TableError, match=r"missing fields \['channels', 'name'\]"):
        BRDFTable.load(partial)
    bad_values = _write_npz(
        tmp_path / "neg.npz", format=np.array(FORMAT_NAME), version=np.array(1),
        values=-np.ones(SHAPE), channels=np.array(["R", "G", "B"]), name=np.array("neg"),
    )
    with pytest.raises(TableError, match=r"neg\.npz: .*negative BRDF values"):
        BRDFTable.load(bad_values)


def test_truncated_file(tmp_path: Path, aniso_table: BRDFTable) -> None:
    path = aniso_table.save(tmp_path / "t.npz")
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    with pytest.raises(TableError, match="not a readable gonio table file"):
        BRDFTable.load(path)


def test_eval_at_grid_points_matches_the_model(aniso_table: BRDFTable) -> None:
    th, td, pd = geo.grid_angles()
    mask = geo.valid_mask()
    for i_ph in (0, 13, 71):
        wi, wo = geo.half_diff_to_directions(th[mask], geo.PH_GRID[i_ph], td[mask], pd[mask])
        np.testing.assert_allclose(aniso_table.eval(wi, wo), ANISO.eval(wi, wo), rtol=1e-6)


def test_eval_off_grid_within_interpolation_error(aniso_table: BRDFTable) -> None:
    rng = np.random.default_rng(11)
    n = 4000
    th = rng.uniform(0, 60 * DEG, n)
    td = rng.uniform(0, 60 * DEG, n)
    ph = rng.uniform(0, 2 * np.pi, n)
    pd = rng.uniform(0, np.pi, n)
    wi, wo = geo.half_diff_to_directions(th, ph, td, pd)
    keep = (wi[:, 2] > np.cos(75 * DEG)) & (wo[:, 2] > np.cos(75 * DEG))
    got = aniso_table.eval(wi[keep], wo[keep])
    want = ANISO.eval(wi[keep], wo[keep])
    rel = np.abs(got - want) / want
    # Multilinear error ~ (h^2 / 8) f'' with h = 5 degrees: small for this smooth lobe.
    assert np.median(rel) < 0.005
    assert np.max(rel) < 0.05


def test_below_horizon_is_zero(aniso_table: BRDFTable) -> None:
    wi = geo.spherical_to_direction(0.3, 0.0)
    wo = geo.spherical_to_direction(1.7, 2.0)  # below the horizon
    assert (aniso_table.eval(wi, wo) == 0).all() and (aniso_table.eval(wo, wi) == 0).all()


def test_periodic_wrap_in_ph_and_pd() -> None:
    t = BRDFTable(ramp_values(), ("R", "G", "B"))
    th, td = geo.TH_GRID[3], geo.TD_GRID[4]
    v = t.values
    # ph: halfway between the last slice (355 deg) and the first (0 = 360 deg).
    got = t.eval_half_diff(th, 357.5 * DEG, td, geo.PD_GRID[5])
    np.testing.assert_allclose(got, 0.5 * (v[:, 71, 3, 4, 5] + v[:, 0, 3, 4, 5]), rtol=1e-9)
    pd5 = geo.PD_GRID[5]
    np.testing.assert_allclose(t.eval_half_diff(th, -5 * DEG, td, pd5), v[:, 71, 3, 4, 5])
    np.testing.assert_allclose(t.eval_half_diff(th, 2 * np.pi, td, pd5), v[:, 0, 3, 4, 5])
    # pd: period pi, so 177.5 deg blends the last pd cell (175) and pd = 0.
    got = t.eval_half_diff(th, geo.PH_GRID[7], td, 177.5 * DEG)
    np.testing.assert_allclose(got, 0.5 * (v[:, 7, 3, 4, 35] + v[:, 7, 3, 4, 0]), rtol=1e-9)
    np.testing.assert_allclose(t.eval_half_diff(th, geo.PH_GRID[7], td, np.pi), v[:, 7, 3, 4, 0])


def test_th_and_td_clamp_at_the_grid_edge() -> None:
    t = BRDFTable(ramp_values(), ("R", "G", "B"))
    np.testing.assert_allclose(
        t.eval_half_diff(-0.1, 0.0, geo.TD_GRID[2], 0.0), t.values[:, 0, 0, 2, 0]
    )


def test_rotation_by_whole_steps_rolls_ph(aniso_table: BRDFTable) -> None:
    turned = aniso_table.rotated(15 * DEG)
    np.testing.assert_array_equal(turned.values, np.roll(aniso_table.values, 3, axis=1))
    assert turned.provenance["rotated_deg"] == pytest.approx(15.0)
    half = aniso_table.rotated(2.5 * DEG)
    mask = geo.valid_mask()
    expected = 0.5 * (aniso_table.values + np.roll(aniso_table.values, 1, axis=1))
    np.testing.assert_allclose(half.values[:, :, mask], expected[:, :, mask], rtol=1e-12)


def test_provenance_is_json(aniso_table: BRDFTable) -> None:
    assert json.loads(json.dumps(aniso_table.provenance))["model"]["type"] == "Rotated"


def test_caller_array_is_neither_changed_nor_frozen() -> None:
    v = np.ones(SHAPE)
    t = BRDFTable(v, ("R", "G", "B"))
    assert v.flags.writeable and (v == 1).all()
    assert np.isnan(t.values[:, :, ~geo.valid_mask()]).all()


def test_trusted_path_takes_the_array_as_is() -> None:
    v = np.where(geo.valid_mask(), 0.5, np.nan) * np.ones(SHAPE)
    t = BRDFTable.trusted(v, ["R", "G", "B"], "fast", (600.0, 550, 450), {"k": 1})
    assert t.values is v and not v.flags.writeable  # no copy, frozen
    assert t.channels == ("R", "G", "B") and t.wavelengths_nm == (600.0, 550.0, 450.0)
    assert t.provenance == {"k": 1} and t.name == "fast"
    # Same object as the validating constructor builds from the same data.
    ref = BRDFTable(v, ("R", "G", "B"), "fast", (600.0, 550.0, 450.0), {"k": 1})
    np.testing.assert_array_equal(t.values, ref.values)
    assert t.channels == ref.channels and t.wavelengths_nm == ref.wavelengths_nm


@pytest.mark.parametrize(
    ("values", "channels", "message"),
    [
        (np.ones((3, 72, 18, 18)), ("R", "G", "B"), r"expected \(C, 72, 18, 18, 36\)"),
        (np.ones(SHAPE), ("R", "G"), r"2 channel names for 3 channels"),
        (np.ones(SHAPE, dtype=np.int64), ("R", "G", "B"), r"float32 or float64"),
    ],
    ids=["shape", "channels", "dtype"],
)
def test_trusted_path_still_checks_shapes(
    values: np.ndarray, channels: tuple[str, ...], message: str
) -> None:
    with pytest.raises(TableError, match=message):
        BRDFTable.trusted(values, channels)


def test_rotated_table_stays_valid(aniso_table: BRDFTable) -> None:
    """Rotation takes the trusted path: its output must pass the full validation anyway."""
    turned = aniso_table.rotated(7.3 * DEG)
    checked = BRDFTable(turned.values, turned.channels, turned.name)
    np.testing.assert_array_equal(checked.values, turned.values)
    assert not turned.values.flags.writeable
