"""Tests of the linear basis: building, off-grid rows, truncation, files, leave-one-out."""

from __future__ import annotations

import functools
import json
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gonio.brdf.reconstruction import basis as basis_mod
from gonio.brdf.reconstruction.basis import (
    Basis,
    BasisError,
    build_basis,
    inverse_remap,
    leave_one_out,
    remap,
)
from gonio.brdf.tables import geometry as geo
from gonio.brdf.tables.table import BRDFTable, from_function

# ---------------------------------------------------------------------------- shared helpers
# test_reconstruct.py imports these; they are plain cached functions, not fixtures, so each
# small table set is built once per test session.


def ward_like(
    kd: tuple[float, float, float], ks: float, ax: float, ay: float, angle: float = 0.0
) -> object:
    """An anisotropic Gaussian lobe over the half vector plus a Lambert term, ``(N, 3)`` out.

    Written here (not taken from gonio.brdf.models.analytic) so these tests only depend on the table
    contract.
    """

    def fn(wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        h = wi + wo
        h = h / np.linalg.norm(h, axis=-1, keepdims=True)
        c, s = np.cos(angle), np.sin(angle)
        hx = c * h[:, 0] + s * h[:, 1]
        hy = -s * h[:, 0] + c * h[:, 1]
        hz = np.maximum(h[:, 2], 1e-6)
        ci = np.maximum(wi[:, 2], 1e-6)
        co = np.maximum(wo[:, 2], 1e-6)
        lobe = ks * np.exp(-((hx / ax) ** 2 + (hy / ay) ** 2) / hz**2)
        lobe = lobe / (4 * np.pi * ax * ay * np.sqrt(ci * co))
        return np.asarray(kd)[None, :] / np.pi + lobe[:, None]

    return fn


@functools.cache
def small_library(n: int = 12) -> tuple[BRDFTable, ...]:
    """``n`` deterministic anisotropic RGB tables with varied colour, gloss and orientation."""
    rng = np.random.default_rng(1234)
    out = []
    for i in range(n):
        kd = tuple(float(x) for x in rng.uniform(0.02, 0.8, 3))
        ax, ay = (float(x) for x in rng.uniform(0.08, 0.5, 2))
        ks = float(rng.uniform(0.05, 0.6))
        angle = float(rng.uniform(0, np.pi))
        out.append(
            from_function(ward_like(kd, ks, ax, ay, angle), ("R", "G", "B"), f"ward-{i:02d}")
        )
    return tuple(out)


@functools.cache
def small_basis(k: int = 16) -> Basis:
    """Basis of all but the first table of :func:`small_library` (the first is held out)."""
    return build_basis(small_library()[1:], k)


def _remapped_training(tables: tuple[BRDFTable, ...], eps: float = 1e-3) -> np.ndarray:
    """Reference: the remapped, centred training matrix (valid rows x columns), float64."""
    valid = geo.valid_mask().ravel()
    A = np.concatenate([t.columns()[:, valid] for t in tables]).T.astype(float)
    f_med = np.median(A, axis=1)
    w = geo.remap_weight(eps).ravel()[valid]
    X = np.log((A * w[:, None] + eps) / (f_med[:, None] * w[:, None] + eps))
    return np.asarray(X - X.mean(axis=1, keepdims=True))


# ---------------------------------------------------------------------------- remap
@settings(max_examples=60, deadline=None)
@given(
    a=st.floats(0.0, 1e4),
    f=st.floats(1e-6, 1e3),
    w=st.floats(1e-3, 1.0),
)
def test_remap_inverse_round_trip(a: float, f: float, w: float) -> None:
    x = remap(a, f, w)
    assert inverse_remap(x, f, w) == pytest.approx(a, rel=1e-9, abs=1e-9)


def test_remap_of_the_median_is_zero() -> None:
    assert remap(0.3, 0.3, 0.5) == pytest.approx(0.0, abs=1e-15)


# ---------------------------------------------------------------------------- building
def test_build_matches_exact_svd_of_the_remapped_matrix() -> None:
    tables = small_library()[:5]
    k = 8
    b = build_basis(tables, k)
    Y = _remapped_training(tables)
    # The exact singular values via the small column-side Gram matrix (360 x 360).
    evals = np.linalg.eigvalsh(Y.T @ Y)[::-1]
    s_exact = np.sqrt(np.maximum(evals[:k], 0))
    np.testing.assert_allclose(b.S, s_exact, rtol=1e-4)
    valid = b.valid
    # Q = U S: the columns are orthogonal with squared norms S^2 ...
    np.testing.assert_allclose(b.Q.T @ b.Q, np.diag(b.S**2), atol=1e-6 * b.S[0] ** 2)
    # ... and span the leading left singular subspace: projecting Y captures its top energy.
    U = b.Q[valid] / b.S
    captured = np.linalg.norm(U.T @ Y) ** 2
    assert captured == pytest.approx(float(np.sum(s_exact**2)), rel=1e-4)


def test_build_fields_and_invalid_rows() -> None:
    b = small_basis()
    valid = geo.valid_mask().ravel()
    assert b.K == 16
    assert b.Q.shape == (geo.N_ROWS, 16)
    assert np.all(b.Q[~valid] == 0)
    assert np.all(np.diff(b.S) <= 0)
    assert b.materials == tuple(t.name for t in small_library()[1:])
    # f_med is the per-row median of the training columns.
    row = int(np.flatnonzero(valid)[1234])
    col = np.concatenate([t.columns()[:, row] for t in small_library()[1:]])
    assert b.f_med[row] == pytest.approx(float(np.median(col)), rel=1e-6)
    assert np.all(b.f_med[~valid] == 0) and np.all(b.mu[~valid] == 0)


def test_build_is_deterministic() -> None:
    a = build_basis(small_library()[:3], 4)
    b = build_basis(small_library()[:3], 4)
    np.testing.assert_array_equal(a.Q, b.Q)


def test_build_rejects_bad_inputs() -> None:
    with pytest.raises(BasisError, match="zero materials"):
        build_basis([], 4)
    t = small_library()[0]
    with pytest.raises(BasisError, match="distinct names"):
        build_basis([t, t], 4)
    with pytest.raises(BasisError, match="n_components"):
        build_basis([t], 0)
    with pytest.raises(BasisError, match="n_components"):
        build_basis([t], 3 * 72 + 1)


def test_build_treats_nan_at_valid_cells_as_the_median() -> None:
    tables = list(small_library()[:3])
    v = np.array(tables[0].values, dtype=float)
    v[:, :, 5, 5, 5] = np.nan  # an unmeasured cell of one material
    tables[0] = BRDFTable(v, tables[0].channels, "holey")
    b = build_basis(tables, 4)
    assert np.isfinite(b.Q).all()


# ---------------------------------------------------------------------------- rows
def test_rows_at_grid_cells_are_the_grid_rows() -> None:
    b = small_basis()
    i = (np.array([3, 10, 0]), np.array([4, 2, 7]), np.array([0, 20, 35]))
    rows = geo.flat_row(*i)
    got = b.rows_at(geo.TH_GRID[i[0]], geo.TD_GRID[i[1]], geo.PD_GRID[i[2]])
    np.testing.assert_allclose(got, b.Q[rows], atol=1e-12)


def test_rows_at_blends_neighbours_and_wraps_pd() -> None:
    b = small_basis()
    th, td = geo.TH_GRID[5], geo.TD_GRID[6]
    mid = b.rows_at([th], [td], [geo.PD_GRID[3] + geo.STEP / 2])[0]
    r3, r4 = geo.flat_row(5, 6, 3), geo.flat_row(5, 6, 4)
    np.testing.assert_allclose(mid, 0.5 * (b.Q[r3] + b.Q[r4]), atol=1e-12)
    # pd is periodic with period pi: 178.75 deg lies between 175 deg (last) and 180 = 0 deg.
    wrap = b.rows_at([th], [td], [np.pi - geo.STEP / 4])[0]
    r_last, r_first = geo.flat_row(5, 6, 35), geo.flat_row(5, 6, 0)
    np.testing.assert_allclose(wrap, 0.25 * b.Q[r_last] + 0.75 * b.Q[r_first], atol=1e-12)
    # th and td clamp at the grid ends: 89 deg uses the 85 deg row.
    clamp = b.rows_at([np.deg2rad(89.0)], [0.0], [0.0])[0]
    np.testing.assert_allclose(clamp, b.Q[geo.flat_row(17, 0, 0)], atol=1e-12)
    # blend() applies the same weights to per-row quantities such as f_med.
    f = b.blend(b.f_med, [th], [td], [geo.PD_GRID[3] + geo.STEP / 2])
    assert f[0] == pytest.approx(0.5 * (b.f_med[r3] + b.f_med[r4]))


def test_rows_at_leaves_out_invalid_neighbours() -> None:
    b = small_basis()
    valid = geo.valid_mask()
    # Find a valid cell whose +th neighbour is invalid (next to the horizon).
    i_th, i_td, i_pd = next(
        (a, c, d)
        for a in range(geo.N_TH - 1)
        for c in range(geo.N_TD)
        for d in range(geo.N_PD)
        if valid[a, c, d] and not valid[a + 1, c, d]
    )
    got = b.rows_at([geo.TH_GRID[i_th] + geo.STEP / 2], [geo.TD_GRID[i_td]], [geo.PD_GRID[i_pd]])
    np.testing.assert_allclose(got[0], b.Q[geo.flat_row(i_th, i_td, i_pd)], atol=1e-12)


def test_rows_at_below_the_horizon_is_an_error() -> None:
    b = small_basis()
    with pytest.raises(BasisError, match="no valid grid neighbour"):
        b.rows_at([np.deg2rad(85.0)], [np.deg2rad(85.0)], [0.0])


def test_truncated() -> None:
    b = small_basis()
    t = b.truncated(5)
    assert t.K == 5
    np.testing.assert_array_equal(t.Q, b.Q[:, :5])
    assert b.truncated(b.K) is b
    with pytest.raises(BasisError, match="cannot keep"):
        b.truncated(b.K + 1)
    with pytest.raises(BasisError, match="cannot keep"):
        b.truncated(0)


# ---------------------------------------------------------------------------- files
def test_save_load_round_trip(tmp_path: Path) -> None:
    b = small_basis()
    p = b.save(tmp_path / "b.npz")
    c = Basis.load(p)
    np.testing.assert_array_equal(c.Q, b.Q)
    np.testing.assert_array_equal(c.S, b.S)
    np.testing.assert_array_equal(c.f_med, b.f_med)
    np.testing.assert_array_equal(c.mu, b.mu)
    assert c.materials == b.materials and c.eps == b.eps
    assert c.provenance["n_materials"] == b.provenance["n_materials"]


def _rewrite(src: Path, dst: Path, **changes: object) -> Path:
    with np.load(src) as z:
        data = {k: z[k] for k in z.files}
    data.update({k: np.asarray(v) for k, v in changes.items()})
    np.savez(dst, **data)  # type: ignore[arg-type]
    return dst


def test_load_refuses_a_basis_from_another_grid(tmp_path: Path) -> None:
    p = small_basis().save(tmp_path / "b.npz")
    bad = _rewrite(p, tmp_path / "grid.npz", grid_deg=[2.5, 36, 36, 72])
    with pytest.raises(BasisError, match="another grid"):
        Basis.load(bad)


def test_load_errors(tmp_path: Path) -> None:
    with pytest.raises(BasisError, match="no such basis file"):
        Basis.load(tmp_path / "missing.npz")
    junk = tmp_path / "junk.npz"
    junk.write_text("not a zip")
    with pytest.raises(BasisError, match="not a readable"):
        Basis.load(junk)
    p = small_basis().save(tmp_path / "b.npz")
    with pytest.raises(BasisError, match="not a gonio basis"):
        Basis.load(_rewrite(p, tmp_path / "fmt.npz", format="something-else"))
    with pytest.raises(BasisError, match="version 7"):
        Basis.load(_rewrite(p, tmp_path / "ver.npz", version=7))
    with pytest.raises(BasisError, match=r"\(11664, K\)"):
        Basis.load(_rewrite(p, tmp_path / "rows.npz", Q=np.zeros((100, 3))))


def test_constructor_checks_shapes() -> None:
    b = small_basis()
    with pytest.raises(BasisError, match="S has shape"):
        Basis(b.Q, b.S[:3], b.f_med, b.mu, b.valid)
    with pytest.raises(BasisError, match="NaN"):
        Basis(np.full_like(b.Q, np.nan), b.S, b.f_med, b.mu, b.valid)


# ---------------------------------------------------------------------------- leave-one-out
def test_leave_one_out_excludes_the_material() -> None:
    tables = small_library()[:4]
    b = leave_one_out(tables, 2, 4)
    assert tables[2].name not in b.materials
    assert len(b.materials) == 3
    assert b.provenance["held_out"] == tables[2].name
    ref = build_basis([tables[0], tables[1], tables[3]], 4)
    np.testing.assert_allclose(b.Q, ref.Q)
    with pytest.raises(BasisError, match="outside"):
        leave_one_out(tables, 4, 4)


# ---------------------------------------------------------------------------- default basis
def test_default_basis_is_cached(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    library = pytest.importorskip("gonio.brdf.materials.library")
    tables = small_library()[:3]
    monkeypatch.setenv("GONIO_CACHE_DIR", str(tmp_path))
    # The real library takes minutes to build; the caching logic is what is under test here.
    monkeypatch.setattr(library, "default_library", lambda progress=False: list(tables))
    b = basis_mod.default_basis(5)
    files = list((tmp_path / "basis").glob("default-K5-*.npz"))
    assert len(files) == 1
    monkeypatch.setattr(library, "default_library", lambda: pytest.fail("rebuilt"))
    again = basis_mod.default_basis(5)
    np.testing.assert_array_equal(again.Q, b.Q)
    assert json.loads(json.dumps(again.provenance, default=str))["file"] == str(files[0])


def test_the_asymmetric_option_trains_on_tables_without_twofold_symmetry(
        monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    library = pytest.importorskip("gonio.brdf.materials.library")
    from gonio.brdf.models import analytic as bm

    tables = list(small_library()[:3])
    leaning = bm.tabulate(bm.Tilted(bm.GGX(0.1, 0.1, bm.DielectricFresnel(1.5)), 0.35, 0.5,
                                    name="leaning"))
    monkeypatch.setenv("GONIO_CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(library, "default_library", lambda progress=False, asymmetric=False:
                        [*tables, leaning] if asymmetric else list(tables))
    plain = basis_mod.synthetic_basis(5)
    asym = basis_mod.synthetic_basis(5, asymmetric=True)
    assert plain.half_turn_periodic and not plain.without_twofold_symmetry
    assert not asym.half_turn_periodic and asym.without_twofold_symmetry == ("leaning",)
    assert len(list((tmp_path / "basis").glob("synthetic-K5-*.npz"))) == 2  # cached apart
    assert basis_mod.default_basis_path(5, asymmetric=True) != basis_mod.default_basis_path(5)


def test_cli_basis_build_rebuilds_the_default_basis_where_it_is_found(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    from gonio.cli import main

    library = pytest.importorskip("gonio.brdf.materials.library")
    tables = small_library()[:3]
    monkeypatch.setenv("GONIO_CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(library, "default_library", lambda progress=False: list(tables))
    assert main(["basis", "build", "-k", "5"]) == 0
    path = basis_mod.default_basis_path(5)
    assert path.is_file()
    monkeypatch.setattr(library, "default_library", lambda progress=False: pytest.fail("rebuilt"))
    b = basis_mod.default_basis(5)
    # The default basis holds the synthetic tables and the shipped measured materials.
    assert {t.name for t in tables} <= set(b.materials)
    assert any(m.startswith("rgl-") for m in b.materials)
    assert b.ph_prior is not None and b.ph_prior.shape == (37, 5, 5)


def test_half_turn_periodic_follows_the_odd_harmonics_of_the_prior() -> None:
    from gonio.brdf.reconstruction.basis import N_HARMONICS, ODD_SHARE_MAX, Basis

    b = small_basis()
    k = b.K
    P = np.zeros((N_HARMONICS, k, k))
    P[0], P[2] = np.eye(k), 0.5 * np.eye(k)
    even = Basis(b.Q, b.S, b.f_med, b.mu, b.valid, b.eps, ph_prior=P.copy())
    assert even.half_turn_periodic
    P[3] = 10 * ODD_SHARE_MAX * np.eye(k)  # a small but real odd share
    assert not Basis(b.Q, b.S, b.f_med, b.mu, b.valid, b.eps, ph_prior=P).half_turn_periodic
    assert Basis(b.Q, b.S, b.f_med, b.mu, b.valid, b.eps).half_turn_periodic  # no prior


def leaning(fn: object, lean: float = 0.8) -> object:
    """``fn`` times ``1 + lean h_x``: brighter towards +x than -x, so the table reads differently
    turned by half a turn (no twofold symmetry; still reciprocal)."""

    def out(wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        h = wi + wo
        h = h / np.linalg.norm(h, axis=-1, keepdims=True)
        return np.asarray(fn(wi, wo)) * (1.0 + lean * h[:, :1])  # type: ignore[operator]

    return out


@functools.cache
def leaning_table() -> BRDFTable:
    """One RGB table without twofold symmetry (a lobe leaning towards +x)."""
    return from_function(leaning(ward_like((0.2, 0.3, 0.4), 0.4, 0.15, 0.3)), ("R", "G", "B"),
                         "leaning-lobe")


def test_bases_name_their_materials_without_twofold_symmetry(tmp_path: Path) -> None:
    from gonio.brdf.reconstruction.basis import fold_in

    base = small_basis()
    # The training tables of small_library are lobes over the half vector: twofold symmetric.
    assert base.half_turn_periodic and base.without_twofold_symmetry == ()
    iso = from_function(lambda wi, wo: np.full((wi.shape[0], 3), 0.3), ("R", "G", "B"), "grey")
    added = fold_in(base, [small_library()[0], iso], 4.0)
    assert added.half_turn_periodic and added.without_twofold_symmetry == ()
    leaned = fold_in(base, [small_library()[0], leaning_table(), iso], 4.0)
    assert not leaned.half_turn_periodic
    assert leaned.without_twofold_symmetry == ("leaning-lobe",)
    # Kept through truncation and a file, and named by a basis built from scratch as well.
    assert leaned.truncated(5).without_twofold_symmetry == ("leaning-lobe",)
    assert Basis.load(leaned.save(tmp_path / "b.npz")).without_twofold_symmetry == (
        "leaning-lobe",)
    built = build_basis([*small_library()[1:4], leaning_table()], 8)
    assert not built.half_turn_periodic
    assert built.without_twofold_symmetry == ("leaning-lobe",)


def test_a_basis_saved_in_float32_reads_back_within_its_rounding(tmp_path: Path) -> None:
    b = basis_mod.build_basis(small_library()[:3], 5)
    path = b.save(tmp_path / "b32.npz", dtype=np.float32)
    with np.load(path) as z:
        assert z["Q"].dtype == np.float32 and z["S"].dtype == np.float64
    back = Basis.load(path)
    assert back.Q.dtype == np.float64
    # float32 keeps 24 bits: a relative rounding of at most 2**-24 of each value, and an
    # absolute one of half the subnormal spacing (2**-150) below its smallest normal value.
    tiny = 2.0**-149
    np.testing.assert_allclose(back.Q, b.Q, rtol=2.0**-24, atol=tiny)
    assert back.ph_prior is not None and b.ph_prior is not None
    np.testing.assert_allclose(back.ph_prior, b.ph_prior, rtol=2.0**-24, atol=tiny)
    np.testing.assert_array_equal(back.S, b.S)
