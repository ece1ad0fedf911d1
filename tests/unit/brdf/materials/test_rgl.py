"""Reading RGL .bsdf measurements into tables (real files from ../shared/data/rgl)."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from gonio.brdf.materials import rgl
from gonio.brdf.models import analytic as bm
from gonio.brdf.tables import geometry as geo
from gonio.brdf.tables.table import BRDFTable, TableError

MATTE = ("acrylic_felt_green_rgb", "colodur_napoli_4f_rgb", "ilm_l3_37_matte_rgb")
GLOSSY = ("cc_ibiza_sunset_rgb", "chm_mint_rgb", "vch_golden_yellow_rgb")


@pytest.fixture(scope="module")
def tables(rgl_dir: Path) -> dict[str, BRDFTable]:
    pytest.importorskip("mitsuba")
    return {p.stem: rgl.read_rgl(p) for p in sorted(rgl_dir.glob("*.bsdf"))}


class _TableModel:
    """Adapter so the model quadrature can integrate a table."""

    def __init__(self, table: BRDFTable) -> None:
        self.table = table
        self.name = table.name
        self.channels = table.channels

    def eval(self, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        return np.nan_to_num(self.table.eval(wi, wo))


def test_all_files_give_finite_nonnegative_isotropic_tables(tables: dict[str, BRDFTable]) -> None:
    assert set(tables) >= set(MATTE) | set(GLOSSY)
    mask = geo.valid_mask()
    for name, table in tables.items():
        assert table.name == name and table.channels == ("R", "G", "B")
        valid = table.values[:, :, mask]
        assert np.isfinite(valid).all() and (valid >= 0).all(), name
        assert np.isnan(table.values[:, :, ~mask]).all()
        np.testing.assert_array_equal(valid, np.broadcast_to(valid[:, :1], valid.shape))
        assert table.provenance["source"] == "rgl"
        assert table.provenance["description"]  # text stored in the file


@pytest.mark.parametrize("name", MATTE)
def test_matte_albedo_is_plausible(tables: dict[str, BRDFTable], name: str) -> None:
    wi = geo.spherical_to_direction(np.deg2rad(30.0), 0.0)
    albedo = bm.directional_albedo(_TableModel(tables[name]), wi, n_theta=90, n_phi=72)
    assert ((albedo > 0.02) & (albedo < 1.0)).all(), albedo


def test_colours_match_the_descriptions(tables: dict[str, BRDFTable]) -> None:
    """Green felt reflects most green; golden yellow film reflects red over blue."""
    mask = geo.valid_mask()
    felt = np.median(tables["acrylic_felt_green_rgb"].values[:, 0][:, mask], axis=1)
    assert felt[1] > felt[0] and felt[1] > felt[2]
    yellow = np.median(tables["vch_golden_yellow_rgb"].values[:, 0][:, mask], axis=1)
    assert yellow[0] > 2 * yellow[2]


@pytest.mark.parametrize("name", GLOSSY)
def test_glossy_films_peak_at_the_mirror_direction(tables: dict[str, BRDFTable], name: str) -> None:
    values = tables[name].values[1, 0]  # green, one ph slice: (th, td, pd)
    i_td = 6  # 30 degrees between light and half vector
    mirror = values[0, i_td, 0]
    off = values[6, i_td, 0]  # half vector 30 degrees off the normal
    assert mirror > 10 * off


def test_missing_file(tmp_path: Path) -> None:
    with pytest.raises(rgl.RGLError, match=r"no such RGL \.bsdf file"):
        rgl.read_rgl(tmp_path / "absent.bsdf")


def test_directory_instead_of_file(tmp_path: Path) -> None:
    with pytest.raises(rgl.RGLError, match="is not a file"):
        rgl.read_rgl(tmp_path)


def test_wrong_header(tmp_path: Path) -> None:
    bad = tmp_path / "fake.bsdf"
    bad.write_bytes(b"<bsdf>xml, not a tensor</bsdf>")
    with pytest.raises(rgl.RGLError, match="not an RGL tensor_file"):
        rgl.read_rgl(bad)


def test_truncated_file_is_refused_before_mitsuba(rgl_dir: Path, tmp_path: Path) -> None:
    """Mitsuba segfaults on truncated tensor files, so this must fail in gonio's own check."""
    src = next(iter(sorted(rgl_dir.glob("*.bsdf"))))
    cut = tmp_path / "cut.bsdf"
    cut.write_bytes(src.read_bytes()[:5000])
    with pytest.raises(rgl.RGLError, match="damaged or truncated tensor_file"):
        rgl.read_rgl(cut)
    header_only = tmp_path / "header.bsdf"
    header_only.write_bytes(src.read_bytes()[:40])
    with pytest.raises(rgl.RGLError, match="header ends early"):
        rgl.read_rgl(header_only)


def test_tensor_file_without_brdf_fields(tmp_path: Path) -> None:
    # A valid container holding one unrelated uint8 field.
    name = b"notes"
    header = b"tensor_file\x00" + bytes([1, 0]) + (1).to_bytes(4, "little")
    offset = len(header) + 2 + len(name) + 2 + 1 + 8 + 8
    field = (
        len(name).to_bytes(2, "little") + name + (1).to_bytes(2, "little") + bytes([1])
        + offset.to_bytes(8, "little") + (3).to_bytes(8, "little")
    )
    path = tmp_path / "other.bsdf"
    path.write_bytes(header + field + b"abc")
    with pytest.raises(rgl.RGLError, match="lacks the fields"):
        rgl.read_rgl(path)


def test_index_of_a_real_file(rgl_dir: Path) -> None:
    index = rgl.read_tensor_index(rgl_dir / "ilm_l3_37_matte_rgb.bsdf")
    assert index["theta_i"]["shape"] == (8,)
    assert index["rgb"]["shape"][-3:] == (3, 32, 32)
    assert "L3-37" in index["description"]["text"]


def test_missing_mitsuba_gives_install_hint(
    rgl_dir: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setitem(sys.modules, "mitsuba", None)  # makes `import mitsuba` fail
    with pytest.raises(rgl.RGLError, match=r"pip install 'gonio\[rgl\]'"):
        rgl.read_rgl(rgl_dir / "ilm_l3_37_matte_rgb.bsdf")


def test_rgl_error_is_a_table_error() -> None:
    assert issubclass(rgl.RGLError, TableError) and issubclass(rgl.RGLError, ValueError)


def test_reciprocity_of_recovers_known_ratios() -> None:
    # Pairs whose exchanged value is the forward one times exp(x) for known x: the statistic
    # is the median and 90th percentile of |x| over the pairs both sides of which are positive.
    rng = np.random.default_rng(3)
    x = rng.uniform(-2.0, 2.0, 1000)
    forward = rng.uniform(0.1, 5.0, (1000, 3))
    exchanged = forward * np.exp(x)[:, None]
    forward[:10] = 0.0  # unlit on one side: left out
    exchanged[10:15] = np.nan
    got = rgl.reciprocity_of(forward, exchanged)
    kept = np.abs(x[15:])
    assert got["pairs"] == 985
    assert got["median_abs_log_ratio"] == pytest.approx(np.median(kept), abs=1e-4)
    assert got["p90_abs_log_ratio"] == pytest.approx(np.percentile(kept, 90), abs=1e-4)
    # Over a subset of the pairs (the steep ones): the same statistics of that subset only.
    steep = np.arange(1000) % 3 == 0
    sub = rgl.reciprocity_of(forward, exchanged, steep=steep)
    kept_steep = np.abs(x[15:][steep[15:]])
    assert sub["median_abs_log_ratio_below_80deg"] == pytest.approx(np.median(kept_steep),
                                                                     abs=1e-4)
    assert sub["p90_abs_log_ratio_below_80deg"] == pytest.approx(
        np.percentile(kept_steep, 90), abs=1e-4)
    assert "median_abs_log_ratio_below_80deg" not in got
    same = rgl.reciprocity_of(forward[15:], forward[15:])
    assert same["median_abs_log_ratio"] == same["p90_abs_log_ratio"] == 0.0
    assert rgl.reciprocity_of(np.zeros((4, 3)), np.ones((4, 3)))["median_abs_log_ratio"] is None


def test_the_files_record_how_far_from_reciprocal_they_are(tables: dict[str, BRDFTable]) -> None:
    """Spot check against mitsuba itself: the exchanged pair evaluated here, at a sample of the
    grid's cells, gives the recorded statistic within the sampling error."""
    mi = pytest.importorskip("mitsuba")
    name = "cm_military_green_rgb"
    rec = tables[name].provenance["reciprocity"]
    assert rec["pairs"] > 0.95 * int(geo.valid_mask().sum())
    assert 0 < rec["median_abs_log_ratio"] < rec["p90_abs_log_ratio"]
    # Grazing cells, whose values the files hold least reliably, carry much of it.
    assert rec["p90_abs_log_ratio_below_80deg"] < rec["p90_abs_log_ratio"]
    th, td, pd = geo.grid_angles()
    mask = geo.valid_mask()
    pick = np.random.default_rng(0).choice(int(mask.sum()), 400, replace=False)
    wi, wo = geo.half_diff_to_directions(th[mask][pick], 0.0, td[mask][pick], pd[mask][pick])
    bsdf = mi.load_dict({"type": "measured", "filename": tables[name].provenance["file"]})
    ctx, si = mi.BSDFContext(), mi.SurfaceInteraction3f()
    ratios = []
    for a, b in zip(wi, wo, strict=True):
        si.wi = mi.Vector3f(*a)
        f = sum(bsdf.eval(ctx, si, mi.Vector3f(*b))) / b[2]
        si.wi = mi.Vector3f(*b)
        g = sum(bsdf.eval(ctx, si, mi.Vector3f(*a))) / a[2]
        if f > 0 and g > 0:
            ratios.append(abs(np.log(f / g)))
    assert np.median(ratios) == pytest.approx(rec["median_abs_log_ratio"], rel=0.25)
    matte = [tables[m].provenance["reciprocity"]["median_abs_log_ratio"] for m in MATTE]
    assert max(matte) < rec["median_abs_log_ratio"]  # the glossy film is the farther one
