"""bench_flipdesign's design cache key holds what a cached design depends on (issue 29).

A design weighted by the render-importance map must be designed again when the map changes
(a change to the renderings), when the rig limits or the arc it is designed for change; an
unweighted one does not depend on the map.
"""

from __future__ import annotations

from pathlib import Path
from types import ModuleType

import numpy as np
import pytest

from gonio.brdf.design.constraints import RigConstraints
from tests.unit.bench_import import import_bench
from tests.unit.brdf.reconstruction.test_basis import small_basis


@pytest.fixture(scope="module")
def benches() -> tuple[ModuleType, ModuleType]:
    """bench_flipdesign and its sibling bench_unseen, imported as the scripts import them."""
    return import_bench("bench_flipdesign"), import_bench("bench_unseen")


def test_the_design_key_changes_with_the_importance_map_the_rig_and_the_arc(
        benches: tuple[ModuleType, ModuleType]) -> None:
    bf, bu = benches
    b = small_basis()
    rig = RigConstraints()
    imp = np.ones((18, 18, 36))
    other = imp.copy()
    other[3, 4, 5] = 2.0  # one node seen by one more pixel
    key = bf.design_key(b, 0.5, imp, 0, rig)
    assert key == bf.design_key(b, 0.5, imp.copy(), 0, rig)
    assert key != bf.design_key(b, 0.5, other, 0, rig)
    assert key != bf.design_key(b, 0.5, imp, 1, rig)
    assert key != bf.design_key(b, 0.5, imp, 0, RigConstraints(max_elevation_deg=70.0))
    # Unweighted (mix 0): the map is not used, so it does not count.
    assert bf.design_key(b, 0.0, imp, 0, rig) == bf.design_key(b, 0.0, other, 0, rig)
    saved = bu.SPAN["design"]
    try:
        bu.SPAN["design"] = 360.0 if saved != 360.0 else 180.0
        assert key != bf.design_key(b, 0.5, imp, 0, rig)
    finally:
        bu.SPAN["design"] = saved


def test_the_design_code_digest_follows_every_module_the_design_runs(
        benches: tuple[ModuleType, ModuleType], tmp_path: Path,
        monkeypatch: pytest.MonkeyPatch) -> None:
    """An edit to a module the design calls (the joint fit's prior, not the design module
    itself) changes the digest; the digest is read from a copy of the package here."""
    import shutil

    import gonio.brdf

    bf, _ = benches
    copy = tmp_path / "brdf"
    shutil.copytree(Path(gonio.brdf.__file__).parent, copy,
                    ignore=shutil.ignore_patterns("*.npz", "__pycache__", "data"))
    monkeypatch.setattr(gonio.brdf, "__file__", str(copy / "__init__.py"))
    before = bf.design_code_digest()
    assert before == bf.design_code_digest()
    joint = copy / "reconstruction" / "joint.py"
    joint.write_text(joint.read_text() + "\n# an edit\n")
    edited = bf.design_code_digest()
    assert edited != before
    (copy / "pictures" / "render.py").write_text("# outside what the design runs\n")
    assert bf.design_code_digest() == edited


@pytest.mark.parametrize(("k", "td"), [(1, 10.0), (2, 12.5)])
def test_the_retro_study_design_forces_its_pairs_first_and_mounts(
        benches: tuple[ModuleType, ModuleType], k: int, td: float) -> None:
    """The retro-pair study's design (docs/notes/2026-11-27-retro-pair.md): ``(0, td, 0)``
    first, with two pairs a second at the same ``td`` and ``th`` in the study's range, ten
    pairs in all, placed under the default rig."""
    from gonio.brdf.design.placement import place_pairs

    bf, _ = benches
    b = small_basis()
    cells, ph = bf.retro_design(b, np.ones((18, 18, 36)), k, td)
    deg = np.rad2deg(cells)
    assert cells.shape == (10, 3) and ph.shape == (10,)
    assert np.allclose(deg[0], [0.0, td, 0.0])
    if k == 2:
        assert np.isclose(deg[1, 1], td) and 5.0 <= deg[1, 0] <= 35.0
    place_pairs(cells, RigConstraints(), ph_step_deg=1.0, seed=0)  # raises if it cannot mount


def test_wins_and_means_count_each_materials_best_preset_per_metric(
        benches: tuple[ModuleType, ModuleType], capsys: pytest.CaptureFixture[str]) -> None:
    """Two materials, two presets: the best preset is taken per material and per metric, and
    a tie is not a win; the mean rows average each kind and all."""
    bf, bu = benches
    mats = [bu.Material("a", "measured", None, None, ()), bu.Material("b", "aniso", None, None, ())]
    s = bu.Score
    rows = {
        "gonio": {"a": s(0.01, 0.0, flip=0.30), "b": s(0.02, 0.0, flip=0.10)},
        "P1": {"a": s(0.02, 0.0, flip=0.20), "b": s(0.02, 0.0, flip=0.40)},
        "P2": {"a": s(0.05, 0.0, flip=0.35), "b": s(0.03, 0.0, flip=0.05)},
    }
    # a: log_rmse 0.01 < min(0.02, 0.05) wins; FLIP 0.30 > 0.20 loses.
    # b: log_rmse 0.02 == min(0.02, 0.03) is a tie, not a win; FLIP 0.10 > 0.05 loses.
    assert bf.best_preset_wins(rows, mats, "gonio", ["P1", "P2"]) == (1, 0)
    assert bf.best_preset_wins(rows, mats, "P2", ["P1"]) == (0, 1)
    bf.print_mean_rows(rows, mats, ["gonio", "P1"])
    out = capsys.readouterr().out.splitlines()
    assert out == ["| **mean measured (1)** | **0.0100 / 0.300** | **0.0200 / 0.200** |",
                   "| **mean aniso (1)** | **0.0200 / 0.100** | **0.0200 / 0.400** |",
                   "| **mean all (2)** | **0.0150 / 0.200** | **0.0200 / 0.300** |"]


def test_each_basis_setting_designs_again_and_is_named_by_its_values(
        benches: tuple[ModuleType, ModuleType]) -> None:
    """The basis-settings study (docs/notes/2026-11-28-basis-flip.md): a basis of another K,
    or of the same K with other components (another measured weight), has its own design key,
    so no setting reads another's cached pairs; the row names say the weight and K, the
    module's defaults filled in."""
    from dataclasses import replace as dc_replace

    from gonio.brdf.reconstruction.basis import DEFAULT_COMPONENTS, MEASURED_WEIGHT

    bf, _ = benches
    b = small_basis()
    rig = RigConstraints()
    imp = np.ones((18, 18, 36))
    key = bf.design_key(b, 0.5, imp, 0, rig)
    assert key != bf.design_key(b.truncated(b.K - 1), 0.5, imp, 0, rig)
    reweighted = dc_replace(b, Q=b.Q * np.linspace(1.0, 1.5, b.K))  # same K, other components
    assert key != bf.design_key(reweighted, 0.5, imp, 0, rig)
    assert bf.setting_name(3.0, 96) == "w=3 K=96"
    assert bf.setting_name(None, None) == f"w={MEASURED_WEIGHT:g} K={DEFAULT_COMPONENTS}"


@pytest.mark.parametrize(("argv", "says"), [
    (["choose", "--measured-weight", "1", "-1"], "--measured-weight: give weights >= 0"),
    (["choose", "--components", "0"], "--components: give K between 1 and 128"),
    (["choose", "--components", "200"], "--components: give K between 1 and 128"),
])
def test_a_bad_basis_setting_is_refused_before_anything_runs(
        benches: tuple[ModuleType, ModuleType], capsys: pytest.CaptureFixture[str],
        argv: list[str], says: str) -> None:
    bf, _ = benches
    with pytest.raises(SystemExit) as exc:
        bf.main(argv)
    assert exc.value.code == 2
    err = capsys.readouterr()
    assert says in err.err
    assert "render importance" not in err.out  # refused before the map is counted


def test_an_eps_setting_is_named_by_it_and_a_bad_eps_is_refused(
        benches: tuple[ModuleType, ModuleType], capsys: pytest.CaptureFixture[str]) -> None:
    """The eps study (docs/notes/2026-11-28-eps-flip.md): the row name says the remap
    constant; a constant outside (0, 1) is refused before any work, saying what to give."""
    bf, _ = benches
    assert bf.setting_name(1.0, 64, 1e-4) == "w=1 K=64 eps=0.0001"
    assert bf.setting_name(None, None, None) == bf.setting_name(None, None)
    for bad in ("0", "1", "1.5"):
        with pytest.raises(SystemExit) as exc:
            bf.main(["choose", "--eps", "1e-3", bad])
        assert exc.value.code == 2
        err = capsys.readouterr()
        assert "--eps: give remap constants between 0 and 1" in err.err
        assert "render importance" not in err.out  # refused before the map is counted


def test_an_eps_basis_is_remapped_with_its_eps_cached_by_it_and_designs_again(
        benches: tuple[ModuleType, ModuleType], tmp_path: Path,
        monkeypatch: pytest.MonkeyPatch) -> None:
    """:func:`eps_default_basis` on a small synthetic library (the default library replaced):
    the synthetic part is centred by the row means of V&F's remap with the asked ``eps``
    (computed here from the formula, not by the code under test), the shipped measured
    tables but the excluded one are folded in, each ``eps`` and each exclusion has its own
    cache file, and bases of two ``eps`` have different design keys."""
    from gonio.brdf.materials import library, measured
    from gonio.brdf.reconstruction.basis import EPS
    from gonio.brdf.tables import geometry
    from tests.unit.brdf.reconstruction.test_basis import small_library

    bf, bu = benches
    lib = small_library()[1:]
    monkeypatch.setattr(library, "default_library", lambda **_: list(lib))
    monkeypatch.setattr(bu, "CACHE", tmp_path / "bench")
    monkeypatch.setenv("GONIO_LIBRARY_DIR", str(tmp_path / "no-user-tables"))
    k = 8
    b4 = bf.eps_default_basis(1e-4, k, exclude=("acrylic_felt_green",))
    assert b4.eps == 1e-4 and k == b4.K
    names = set(b4.materials)
    shipped = {t.name for t in measured.measured_tables()}
    assert "rgl-acrylic_felt_green" not in names
    assert shipped - {"rgl-acrylic_felt_green"} <= names
    assert {t.name for t in lib} <= names

    # The synthetic part: mu is the row mean of ln((A w + eps) / (f_med w + eps)), eps = 1e-4.
    base = bf.eps_synthetic(1e-4, k + 32)
    valid = geometry.valid_mask().ravel()
    A = np.concatenate([t.columns()[:, valid] for t in lib]).T.astype(float)
    f_med = np.median(A, axis=1, keepdims=True)

    def row_mean(eps: float) -> np.ndarray:
        w = np.maximum(geometry.remap_weight(eps).ravel()[valid], eps)[:, None]
        return np.asarray(np.log((A * w + eps) / (f_med * w + eps)).mean(axis=1))

    assert np.allclose(base.mu[valid], row_mean(1e-4), atol=1e-4)
    assert not np.allclose(base.mu[valid], row_mean(EPS), atol=1e-4)

    # Cached per eps and per exclusion: a second call reads the file, others build their own.
    files = sorted(p.name for p in (tmp_path / "bench").rglob("*.npz"))
    assert len(files) == 2 and all("eps0.0001" in f for f in files)
    again = bf.eps_default_basis(1e-4, k, exclude=("acrylic_felt_green",))
    assert np.array_equal(again.Q, b4.Q)
    assert len(list((tmp_path / "bench").rglob("*.npz"))) == 2
    b5 = bf.eps_default_basis(1e-5, k, exclude=("acrylic_felt_green",))
    bf.eps_default_basis(1e-4, k, exclude=("chm_orange",))
    assert len(list((tmp_path / "bench").rglob("*.npz"))) == 5
    assert b5.eps == 1e-5

    rig = RigConstraints()
    imp = np.ones((18, 18, 36))
    assert bf.design_key(b4, 0.5, imp, 0, rig) != bf.design_key(b5, 0.5, imp, 0, rig)


def test_today_s_eps_is_the_default_basis_itself(
        benches: tuple[ModuleType, ModuleType], monkeypatch: pytest.MonkeyPatch) -> None:
    """``eps`` None or the product's EPS reads ``default_basis`` (today's basis, its shipped
    synthetic part included), with the same K, exclusion and weight."""
    from gonio.brdf.reconstruction.basis import EPS

    bf, _ = benches
    calls: list[tuple[object, ...]] = []
    monkeypatch.setattr(bf, "default_basis", lambda k, exclude=(), measured_weight=None:
                        calls.append((k, tuple(exclude), measured_weight)) or "default")
    assert bf.eps_default_basis(EPS, 64, ("chm_orange",), 2.0) == "default"
    assert bf.eps_default_basis(None, None) == "default"
    assert calls == [(64, ("chm_orange",), 2.0), (None, (), None)]


def _remapped_mean(tables: tuple[object, ...], eps: float = 1e-3) -> np.ndarray:
    """Row means of V&F's remap ``ln((A w + eps) / (f_med w + eps))`` over the tables' columns
    at the valid cells (from the formula, not the code under test)."""
    from gonio.brdf.tables import geometry

    valid = geometry.valid_mask().ravel()
    A = np.concatenate([t.columns()[:, valid] for t in tables]).T.astype(float)  # type: ignore[attr-defined]
    f_med = np.median(A, axis=1, keepdims=True)
    w = np.maximum(geometry.remap_weight(eps).ravel()[valid], eps)[:, None]
    return np.asarray(np.log((A * w + eps) / (f_med * w + eps)).mean(axis=1))


def test_the_render_weighted_basis_is_the_weighted_pca_of_the_remapped_matrix(
        benches: tuple[ModuleType, ModuleType]) -> None:
    """Learned inside ``_RowScaled(d)``, the basis' components are those of the exact SVD of
    ``sqrt(d) Y`` (``Y`` the remapped, centred training matrix, computed here from V&F's
    formula), taken back by ``1 / sqrt(d)``: the singular values agree and ``sqrt(d) Q``
    spans the same space; they differ from the unweighted basis'."""
    from gonio.brdf.reconstruction.basis import build_basis
    from gonio.brdf.tables import geometry
    from tests.unit.brdf.reconstruction.test_basis import _remapped_training, small_library

    bf, _ = benches
    lib = small_library()[1:7]
    k = 6
    valid = geometry.valid_mask().ravel()
    d = np.ones(geometry.N_ROWS)
    d[valid] = np.random.default_rng(5).uniform(0.05, 20.0, int(valid.sum()))
    scale = bf._RowScaled(d)
    with scale:
        b = scale.unscaled(build_basis(lib, k), 0.5, mu_scaled=False)
    s = np.sqrt(d[valid])[:, None]
    U, S, _ = np.linalg.svd(s * _remapped_training(lib), full_matrices=False)
    assert np.allclose(b.S, S[:k], rtol=1e-3)
    sq = s * b.Q[valid]
    proj = U[:, :k] @ (U[:, :k].T @ sq)
    assert np.linalg.norm(sq - proj) < 1e-3 * np.linalg.norm(sq)
    plain = build_basis(lib, k)
    assert not np.allclose(plain.S, b.S, rtol=1e-2)
    # The row means do not depend on row weights: the centring is V&F's, from the formula.
    assert np.allclose(b.mu[valid], _remapped_mean(lib), atol=1e-5)
    assert b.provenance["render_strength"] == 0.5
    # The patch is gone after the block: the same build is the plain one again.
    assert np.allclose(build_basis(lib, k).S, plain.S)


def test_a_weighted_fold_in_keeps_the_weighted_components_orthogonal(
        benches: tuple[ModuleType, ModuleType]) -> None:
    """``fold_in`` inside ``_RowScaled(d)``: ``sqrt(d) Q`` has orthogonal columns of norms
    ``S`` (a weighted PCA's), the row mean is the plain fold-in's (a per-row mean does not
    depend on row weights), and a constant weight gives the plain fold-in's basis."""
    from gonio.brdf.reconstruction.basis import build_basis, fold_in
    from gonio.brdf.tables import geometry
    from tests.unit.brdf.reconstruction.test_basis import small_library

    bf, _ = benches
    lib = small_library()
    k = 6
    valid = geometry.valid_mask().ravel()
    d = np.ones(geometry.N_ROWS)
    d[valid] = np.random.default_rng(6).uniform(0.05, 20.0, int(valid.sum()))
    scale = bf._RowScaled(d)
    with scale:
        base = scale.unscaled(build_basis(lib[1:7], k + 4), 0.5, mu_scaled=False)
    with scale:
        b = scale.unscaled(fold_in(scale.scaled(base), [lib[0]], 2.0, k), 0.5)
    sq = np.sqrt(d[valid])[:, None] * b.Q[valid]
    gram = sq.T @ sq
    assert np.allclose(gram, np.diag(b.S ** 2), atol=1e-8 * b.S[0] ** 2)
    plain = fold_in(base, [lib[0]], 2.0, k)
    assert np.allclose(b.mu, plain.mu, atol=1e-10)
    # ... and are the plain build's: the synthetic part's are the formula's.
    assert np.allclose(base.mu[valid], _remapped_mean(lib[1:7]), atol=1e-5)
    assert not np.allclose(plain.S, b.S, rtol=1e-2)
    flat = bf._RowScaled(np.full(geometry.N_ROWS, 4.0))
    with flat:
        same = flat.unscaled(fold_in(flat.scaled(plain), [], 2.0, k), 0.0)
    assert np.allclose(same.Q, plain.Q, atol=1e-12)


def test_the_weighted_ceiling_with_equal_weights_is_the_plain_one_and_bad_strengths_fail(
        benches: tuple[ModuleType, ModuleType]) -> None:
    """``weighted_ceiling`` with a constant weight is bench_unseen's least-squares ceiling;
    a heavier weight on a set of cells fits them closer; a strength outside [0, 1) is a
    ValueError naming the range."""
    from gonio.brdf.tables import geometry
    from tests.unit.brdf.reconstruction.test_basis import small_library

    bf, bu = benches
    b = small_basis(8)
    truth = small_library()[0]
    plain = bu.ceiling(b, truth)
    same = bf.weighted_ceiling(b, truth, np.full(geometry.N_ROWS, 3.0))
    assert np.allclose(same.values, plain.values, rtol=1e-8, equal_nan=True)
    d = np.ones(geometry.N_ROWS)
    heavy = np.zeros(geometry.N_ROWS, dtype=bool)
    heavy[geometry.valid_mask().ravel()] = True
    heavy[: geometry.N_ROWS // 2] = False
    d[heavy] = 1e4
    t = np.asarray(truth.values).reshape(3, geometry.N_PH, geometry.N_ROWS)

    def err(table: object) -> float:
        v = np.asarray(table.values).reshape(3, geometry.N_PH, geometry.N_ROWS)  # type: ignore[attr-defined]
        return float(np.mean((np.log1p(v[:, :, heavy]) - np.log1p(t[:, :, heavy])) ** 2))

    assert err(bf.weighted_ceiling(b, truth, d)) < err(plain)
    with pytest.raises(ValueError, match=r"\[0, 1\)"):
        bf.render_row_weight(1.0)
    # d = (1 - A) + A c / mean(c): averages 1 on the valid cells; an unseen cell gets 1 - A.
    from gonio.brdf.pictures.appearance import render_importance

    valid = geometry.valid_mask().ravel()
    w = bf.render_row_weight(0.9)
    unseen = valid & (np.asarray(render_importance()).ravel() == 0)
    assert w[valid].mean() == pytest.approx(1.0) and np.allclose(w[unseen], 0.1)
    assert np.array_equal(bf.render_row_weight(0.0), np.ones(geometry.N_ROWS))
