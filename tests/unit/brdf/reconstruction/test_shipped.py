"""Tests of the shipped synthetic basis: it matches the code that builds it, and a fresh install
(or a user import) gets the default basis from it without building the library."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from gonio.brdf.materials import library, measured
from gonio.brdf.reconstruction import basis as basis_mod
from gonio.brdf.reconstruction import shipped
from gonio.brdf.tables import geometry as geo
from tests.unit.brdf.reconstruction.test_basis import small_library


def test_the_shipped_basis_was_built_by_this_code() -> None:
    recorded = shipped.recorded()
    assert recorded["fingerprint"] == shipped.fingerprint(), (
        "the code or parameters that build the shipped synthetic basis changed "
        f"({', '.join(shipped.SOURCE_MODULES)}), but {shipped.SHIPPED_FILE.name} was not "
        f"rebuilt: run `{shipped.REBUILD_COMMAND}` and commit both files in "
        f"{shipped.DATA_DIR.relative_to(Path(shipped.__file__).parents[3])}"
    )
    # The fingerprint file describes the very file beside it (written together).
    assert recorded["sha256"] == shipped.file_sha256(), (
        f"{shipped.SHIPPED_FILE.name} is not the file its fingerprint was recorded for: "
        f"run `{shipped.REBUILD_COMMAND}`")
    assert shipped.is_current()


def test_the_shipped_file_is_small_float32_and_holds_the_library() -> None:
    size = shipped.SHIPPED_FILE.stat().st_size
    assert size < 6e6, f"the shipped basis takes {size / 1e6:.1f} MB; keep it a few MB"
    with np.load(shipped.SHIPPED_FILE) as z:
        assert z["Q"].dtype == np.float32 and z["ph_prior"].dtype == np.float32
    b = shipped.shipped_basis(shipped.SHIPPED_COMPONENTS)
    assert b is not None and b.K == shipped.SHIPPED_COMPONENTS
    assert b.Q.dtype == np.float64  # read back as float64 for the solvers
    assert list(b.materials) == [s.name for s in library.library_specs()]
    assert b.ph_prior is not None and b.half_turn_periodic
    # No machine path or build time is committed in its provenance.
    with np.load(shipped.SHIPPED_FILE) as z:
        prov = str(z["provenance"])
    assert "build_seconds" not in prov and '"file"' not in prov
    # Another K is not the shipped one.
    assert shipped.shipped_basis(shipped.SHIPPED_COMPONENTS - 1) is None


def test_the_code_text_ignores_comments_and_docstrings_only() -> None:
    base = 'def f(x):\n    """Doc."""\n    return x + 1\n'
    assert shipped.code_text(base) == "def f(x):\n    return x + 1"
    assert shipped.code_text(base) == shipped.code_text(
        '# header\ndef f(x):\n    """Other words, Vávra,\n    two lines."""\n\n'
        "    return x + 1  # why\n")
    assert shipped.code_text(base) != shipped.code_text(base.replace("+ 1", "+ 2"))
    # A string that is not a docstring is code, and so is a "#" inside a string.
    assert shipped.code_text('x = "a"\n') != shipped.code_text('x = "b"\n')
    assert shipped.code_text('x = "#1"  # note\n') == 'x = "#1"'
    # Columns after non-ASCII text: ast counts bytes, the cut must count characters.
    assert shipped.code_text('y = "é"; """not a docstring"""\n') == 'y = "é"; """not a docstring"""'
    assert shipped.code_text('"""Modul é."""\nx = 1\n') == "x = 1"


def test_a_stale_shipped_basis_is_not_used(monkeypatch: pytest.MonkeyPatch,
                                           tmp_path: Path) -> None:
    monkeypatch.setenv("GONIO_CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(shipped, "fingerprint", lambda: "0" * 64)  # as if the code changed
    assert not shipped.is_current()
    assert shipped.shipped_basis(shipped.SHIPPED_COMPONENTS) is None
    tables = small_library()[:3]
    monkeypatch.setattr(library, "default_library", lambda progress=False: list(tables))
    b = basis_mod.synthetic_basis(shipped.SHIPPED_COMPONENTS)  # built from the "library"
    assert b.materials == tuple(t.name for t in tables)
    assert shipped.main(["--check"]) == 1


def test_a_fresh_install_and_an_import_fold_into_the_shipped_basis(
        monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.setenv("GONIO_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.setenv("GONIO_LIBRARY_DIR", str(tmp_path / "lib"))
    monkeypatch.setattr(library, "default_library",
                        lambda *a, **k: pytest.fail("the library was built"))
    monkeypatch.setattr(library, "build_library",
                        lambda *a, **k: pytest.fail("the library was built"))
    b = basis_mod.default_basis()
    synthetic = [s.name for s in library.library_specs()]
    assert list(b.materials) == [*synthetic, *measured.measured_names()]
    assert b.K == basis_mod.DEFAULT_COMPONENTS
    assert basis_mod.default_basis_path().is_file()  # cached for the next scans
    # The shipped part is the leading subspace: the first component of the default basis lies
    # almost entirely in the span of the shipped synthetic one (11 measured materials against
    # 175 synthetic ones move it little).
    syn = shipped.shipped_basis(shipped.SHIPPED_COMPONENTS)
    assert syn is not None
    rows = np.flatnonzero(b.valid)
    U, _ = np.linalg.qr(syn.Q[rows])
    q = b.Q[rows, 0] / np.linalg.norm(b.Q[rows, 0])
    assert np.linalg.norm(U.T @ q) > 0.99
    # A user import changes the default basis' key; the new one folds in the import, again
    # without building the library.
    (tmp_path / "lib").mkdir()
    small_library()[0].save(tmp_path / "lib" / "mine.npz")
    path = basis_mod.default_basis_path()
    assert not path.is_file()
    again = basis_mod.default_basis()
    assert small_library()[0].name in again.materials and path.is_file()


@pytest.mark.slow
def test_the_shipped_basis_is_the_leading_subspace_of_the_library() -> None:
    """The shipped basis against the tabulated library it claims to summarise (minutes on a
    fresh cache, where the library test builds the library too), checked without running the
    builder's randomized SVD again: from the library's slice matrix, remapped and centred as
    math.md 4 defines it (written out here), the shipped row medians and means come back, and
    each shipped component is a singular pair of that matrix, ``Y Y^T u = s^2 u`` with
    ``|Y^T u| = s``; nothing outside the shipped span is as strong as its leading components.

    Two passes over the data instead of the build's eight and its QR factorisations (about a
    third of the CPU). Float32 data and a randomized SVD's accuracy set the tolerances: the
    measured residuals are 2e-3 (leading 64 components) and 3e-6 (singular values).
    """
    tables = library.default_library()
    syn = shipped.shipped_basis(shipped.SHIPPED_COMPONENTS)
    assert syn is not None
    assert list(syn.materials) == [t.name for t in tables]
    rows = np.flatnonzero(geo.valid_mask().ravel())
    # Every channel of every ph slice of every material is one column (p rows, m columns).
    m = sum(t.n_channels * geo.N_PH for t in tables)
    Y = np.empty((rows.size, m), dtype=np.float32)
    j = 0
    for t in tables:
        cols = t.columns()[:, rows]
        Y[:, j:j + cols.shape[0]] = cols.T
        j += cols.shape[0]
    f_med = np.median(Y, axis=1)
    np.testing.assert_allclose(syn.f_med[rows], f_med, rtol=1e-6, atol=1e-9)
    w = basis_mod.row_weight(syn.eps)[rows]
    for r0 in range(0, rows.size, 512):  # Eq. 1 in row blocks, so temporaries stay small
        blk = slice(r0, r0 + 512)
        Y[blk] = basis_mod.remap(Y[blk], f_med[blk, None], w[blk, None], syn.eps)
    mu = Y.mean(axis=1, dtype=np.float64)
    np.testing.assert_allclose(syn.mu[rows], mu, atol=1e-6)
    Y -= mu[:, None].astype(np.float32)

    S = syn.S
    U = syn.Q[rows] / S  # unit left singular vectors (the file keeps U S)
    np.testing.assert_allclose(U.T @ U, np.eye(S.size), atol=1e-5)
    G = (Y.T @ U.astype(np.float32)).astype(np.float64)  # (m, K): Y^T u for every component
    np.testing.assert_allclose(np.linalg.norm(G, axis=0), S, rtol=1e-4)
    rayleigh = G.T @ G / np.outer(S, S)
    np.testing.assert_allclose(rayleigh, np.eye(S.size), atol=1e-4)
    k = basis_mod.DEFAULT_COMPONENTS
    YYtU = (Y @ G[:, :k].astype(np.float32)).astype(np.float64)
    residual = np.linalg.norm(YYtU - U[:, :k] * S[:k] ** 2, axis=0) / S[:k] ** 2
    assert residual.max() < 1e-2, residual
    # What the shipped components leave: a few block power steps from random probes find
    # nothing as strong as the K-th leading component.
    rng = np.random.default_rng(1)
    Z = rng.standard_normal((rows.size, 8))
    for _ in range(4):
        Z -= U @ (U.T @ Z)
        Z = np.linalg.qr(Z)[0]
        Z = (Y @ (Y.T @ Z.astype(np.float32))).astype(np.float64)
    Z -= U @ (U.T @ Z)
    Z = np.linalg.qr(Z)[0]
    left = np.linalg.norm((Y.T @ Z.astype(np.float32)).astype(np.float64), axis=0)
    assert left.max() < S[k - 1], (left, S[k - 1])
