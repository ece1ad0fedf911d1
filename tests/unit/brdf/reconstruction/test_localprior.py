"""Local priors: each folded-in material's isotropic covariance, chosen per scan by evidence."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from gonio.brdf.reconstruction.basis import Basis, BasisError, fold_in, remap, row_weight
from gonio.brdf.reconstruction.localprior import (
    EVIDENCE,
    LOCAL_SHARE,
    choose_local_prior,
    layout_takes_local_priors,
    out_of_plane_share,
)
from gonio.brdf.reconstruction.posterior import ScanPosterior
from gonio.brdf.reconstruction.reconstruct import ReconstructionError, reconstruct
from gonio.brdf.reconstruction.samples import NoiseModel, simulate_samples, uniform_stage_angles
from gonio.brdf.tables import geometry as geo
from gonio.brdf.tables import metrics
from gonio.brdf.tables.table import BRDFTable, from_function
from tests.unit.brdf.reconstruction.test_basis import small_basis, small_library, ward_like
from tests.unit.brdf.reconstruction.test_posterior import _dense_prior_readings
from tests.unit.brdf.reconstruction.test_reconstruct import grid_pairs


def _grey() -> BRDFTable:
    return from_function(lambda wi, wo: np.full((wi.shape[0], 3), 0.3), ("R", "G", "B"), "grey")


def _sharp() -> BRDFTable:
    """A glossy, nearly isotropic lobe unlike the small library's broad ones."""
    return from_function(ward_like((0.05, 0.04, 0.03), 0.9, 0.05, 0.06, 0.3), ("R", "G", "B"),
                         "sharp")


def _folded() -> Basis:
    return fold_in(small_basis(), [small_library()[0], _grey(), _sharp()], 4.0)


def _channel_means(b: Basis, t: BRDFTable) -> np.ndarray:
    """Reference: least-squares coefficients of every slice of ``t`` in ``b`` (numpy's lstsq
    on the remapped, centred values), averaged over ``ph``: (C, K)."""
    rows = np.flatnonzero(b.valid)
    v = np.asarray(t.values, dtype=float).reshape(t.n_channels, geo.N_PH, geo.N_ROWS)[:, :, rows]
    x = remap(v, b.f_med[rows], row_weight(b.eps)[rows], b.eps) - b.mu[rows]
    return np.stack([np.linalg.lstsq(b.Q[rows], x[c].T, rcond=None)[0].mean(axis=1)
                     for c in range(t.n_channels)])


def _isotropic_second_moment(b: Basis, t: BRDFTable) -> np.ndarray:
    """Reference: the outer products of :func:`_channel_means` summed over the channels."""
    m = _channel_means(b, t)
    return np.asarray(m.T @ m)


def test_fold_in_keeps_each_added_materials_isotropic_covariance() -> None:
    tables = [small_library()[0], _grey(), _sharp()]
    b = _folded()
    assert b.local_names == ("ward-00", "grey", "sharp")
    assert b.local_priors is not None and b.local_priors.shape == (3, b.K, b.K)
    assert b.ph_prior is not None
    size = np.trace(b.ph_prior[0])
    for t, got in zip(tables, b.local_priors, strict=True):
        want = _isotropic_second_moment(b, t)
        want *= size / np.trace(want)  # scaled to the whole prior's isotropic size
        np.testing.assert_allclose(got, want, rtol=1e-6, atol=1e-9 * size)
    # A basis built from scratch or with nothing folded in has none.
    assert small_basis().local_priors is None and small_basis().local_names == ()
    assert fold_in(small_basis(), [], 4.0).local_priors is None


def test_folding_in_twice_carries_the_first_tables() -> None:
    """The first fold's tables, carried through a second fold (the mean shift included), have
    the coefficients the second basis gives them directly, up to what the first fold's
    truncation to K components lost of them; the second fold's own are exact."""
    once = fold_in(small_basis(), [_grey()], 4.0)
    twice = fold_in(once, [_sharp()], 4.0)
    assert twice.local_names == ("grey", "sharp")
    assert twice.local_means is not None
    grey = _channel_means(twice, _grey())
    assert np.linalg.norm(twice.local_means[0] - grey) < 0.01 * np.linalg.norm(grey)
    # Without the shift of the mean the carried rows would be far off (this test's point).
    assert once.local_means is not None
    rows_once, rows_twice = np.flatnonzero(once.valid), np.flatnonzero(twice.valid)
    T = np.linalg.pinv(twice.Q[rows_twice]) @ once.Q[rows_once]
    unshifted = once.local_means[0] @ T.T
    assert np.linalg.norm(unshifted - grey) > 0.1 * np.linalg.norm(grey)
    sharp = _channel_means(twice, _sharp())
    np.testing.assert_allclose(twice.local_means[1], sharp, rtol=1e-6,
                               atol=1e-9 * np.abs(sharp).max())


def test_local_priors_survive_a_file_and_truncation(tmp_path: Path) -> None:
    b = _folded()
    back = Basis.load(b.save(tmp_path / "b.npz"))
    assert back.local_names == b.local_names
    assert back.local_priors is not None and b.local_priors is not None
    np.testing.assert_array_equal(back.local_priors, b.local_priors)
    cut = b.truncated(5)
    assert cut.local_priors is not None and cut.local_names == b.local_names
    assert cut.ph_prior is not None
    # Still each its table's second moment in the first five components, scaled to the
    # truncated prior's isotropic size.
    size = np.trace(cut.ph_prior[0])
    for got, t in zip(cut.local_priors, (small_library()[0], _grey(), _sharp()), strict=True):
        want = _isotropic_second_moment(b, t)[:5, :5]
        np.testing.assert_allclose(got, want * size / np.trace(want), rtol=1e-6,
                                   atol=1e-9 * size)


def test_a_basis_file_with_broken_local_priors_is_refused_with_the_fix(tmp_path: Path) -> None:
    b = _folded()
    path = b.save(tmp_path / "b.npz")
    with np.load(path) as z:
        data = dict(z)
    data["local_means"] = data["local_means"][:, :, :3]  # wrong shape
    bad = tmp_path / "bad.npz"
    np.savez(bad, **data)
    with pytest.raises(BasisError, match=r"local_means.*rebuild"):
        Basis.load(bad)
    with pytest.raises(BasisError, match="local_names given without local_means"):
        Basis(b.Q, b.S, b.f_med, b.mu, b.valid, b.eps, b.materials, b.provenance, b.ph_prior,
              None, ("x",))


def test_the_isotropic_marginal_likelihood_is_the_gaussian_one() -> None:
    """log_marginal_isotropic(P0) is the profiled Gaussian log likelihood of the readings with
    the readings' covariance written out element by element for the prior with P_0 replaced."""
    b = _folded()
    cells, ph = grid_pairs(6, seed=2)
    alpha = uniform_stage_angles(5)
    vals = simulate_samples(small_library()[3], cells, ph, alpha,
                            noise=NoiseModel(0.01, seed=1))
    post = ScanPosterior(b, cells, ph, alpha, vals)
    assert post.log_marginal_isotropic(post.P[0]) == pytest.approx(
        post.log_marginal(post.rho, post.rho_high), rel=1e-9)
    assert b.local_priors is not None
    P0 = 0.5 * post.P[0] + 0.5 * b.local_priors[2]
    other = ScanPosterior(b, cells, ph, alpha, vals, rho=(post.rho, post.rho_high),
                          prior=np.concatenate([P0[None], post.P[1:]]))
    G = _dense_prior_readings(other, alpha, post.rho, post.rho_high)
    G += post.eta * np.eye(G.shape[0])
    y = post.y
    N, C = y.shape
    s2 = float(np.sum(y * np.linalg.solve(G, y))) / (N * C)
    want = -0.5 * N * C * np.log(s2) - 0.5 * C * np.linalg.slogdet(G)[1]
    assert post.log_marginal_isotropic(P0) == pytest.approx(want, rel=1e-9)


def _scan(t: BRDFTable) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    cells, ph = grid_pairs(6, seed=11)
    alpha = uniform_stage_angles(8)
    return cells, ph, alpha, simulate_samples(t, cells, ph, alpha,
                                              noise=NoiseModel(0.01, seed=3))


def _sharp_cousin() -> BRDFTable:
    """A lobe like :func:`_sharp` (a little wider, another colour), in no basis."""
    return from_function(ward_like((0.08, 0.03, 0.05), 0.8, 0.07, 0.08, 1.1), ("R", "G", "B"),
                         "sharp-cousin")


def test_a_scan_of_a_folded_in_material_leans_on_its_own_prior() -> None:
    """A specimen like the sharp lobe, which is unlike the library it was folded into: its
    readings favour the sharp lobe's isotropic covariance over the library's by far more than
    the evidence asks for, and the fit records the one it leaned on. (Whether leaning makes
    the table closer to the truth is the benchmark's question, docs/science.md 7.2.3: here it
    does not, the cousin's colour being outside the sharp lobe's three channels.)"""
    b = _folded()
    truth = _sharp_cousin()
    cells, ph, alpha, vals = _scan(truth)
    post = ScanPosterior(b, cells, ph, alpha, vals)
    pick = choose_local_prior(post, b)
    assert pick is not None and pick.name == "sharp"
    assert pick.gain >= np.log(EVIDENCE * 3)
    assert b.local_priors is not None
    np.testing.assert_allclose(
        pick.prior[0], (1 - LOCAL_SHARE) * post.P[0] + LOCAL_SHARE * b.local_priors[2])
    np.testing.assert_array_equal(pick.prior[1:], post.P[1:])
    leaned = reconstruct(b, cells, ph, alpha, vals)
    plain = reconstruct(b, cells, ph, alpha, vals, local=None)
    assert leaned.settings["local_prior"] == "sharp"
    assert leaned.settings["local_prior_note"] == "leaned"
    assert leaned.settings["local_prior_gain"] == pytest.approx(pick.gain, abs=1e-3)
    assert plain.settings["local_prior"] is None
    assert not np.array_equal(leaned.table.values, plain.table.values)


def test_leaning_on_the_specimens_own_table_brings_the_fit_closer() -> None:
    """The specimen is one of the folded-in tables: leaning on its own shape, the fit is
    closer to it than the library prior's fit of the same readings."""
    b = _folded()
    cells, ph, alpha, vals = _scan(_sharp())
    leaned = reconstruct(b, cells, ph, alpha, vals)
    plain = reconstruct(b, cells, ph, alpha, vals, local=None)
    assert leaned.settings["local_prior"] == "sharp"
    assert metrics.log_rmse(leaned.table, _sharp()) < metrics.log_rmse(plain.table, _sharp())


def test_the_evidence_is_counted_per_three_channels() -> None:
    """The same readings copied into more channels carry no more information: the gain per
    three channels, and the choice, stay those of the RGB scan."""
    b = _folded()
    cells, ph, alpha, vals = _scan(_sharp_cousin())
    rgb = choose_local_prior(ScanPosterior(b, cells, ph, alpha, vals), b)
    many = np.concatenate([vals] * 4, axis=2)  # 12 channels
    twelve = choose_local_prior(ScanPosterior(b, cells, ph, alpha, many), b)
    assert rgb is not None and twelve is not None and twelve.name == rgb.name
    assert twelve.gain == pytest.approx(rgb.gain, rel=1e-6)


def test_without_strong_evidence_the_library_prior_stays() -> None:
    """Readings drowned in noise say nothing about the material: no local prior is chosen and
    the fit is the library prior's, value for value; so is any fit with local=None."""
    b = _folded()
    cells, ph, alpha, _ = _scan(_sharp())
    vals = np.abs(np.random.default_rng(4).normal(0.5, 0.25, (cells.shape[0], alpha.size, 3)))
    rec = reconstruct(b, cells, ph, alpha, vals)
    assert rec.settings["local_prior"] is None
    assert rec.settings["local_prior_note"] == "no folded-in table favoured by strong evidence"
    off = reconstruct(b, cells, ph, alpha, vals, local=None)
    assert off.settings["local_prior_note"] == "not asked"
    np.testing.assert_array_equal(rec.table.values, off.table.values)
    # The basis without local priors fits the same scan the same way.
    bare = Basis(b.Q, b.S, b.f_med, b.mu, b.valid, b.eps, b.materials, b.provenance, b.ph_prior)
    cells, ph, alpha, vals = _scan(_sharp())
    bare_fit = reconstruct(bare, cells, ph, alpha, vals)
    assert bare_fit.settings["local_prior_note"] == "the basis holds no folded-in tables"
    np.testing.assert_array_equal(
        bare_fit.table.values,
        reconstruct(b, cells, ph, alpha, vals, local=None).table.values)


def test_an_unknown_local_setting_is_refused() -> None:
    cells, ph, alpha, vals = _scan(_grey())
    with pytest.raises(ReconstructionError, match="local must be 'scan' or None"):
        reconstruct(_folded(), cells, ph, alpha, vals, local="yes")  # type: ignore[arg-type]


def test_the_share_of_pairs_out_of_the_plane_of_incidence() -> None:
    # pd 0, 5 and 175 degrees lie within 10 degrees of the plane; 30 and 90 do not.
    cells = np.deg2rad([[10.0, 20.0, 0.0], [10.0, 20.0, 5.0], [10.0, 20.0, 175.0],
                        [10.0, 20.0, 30.0], [10.0, 20.0, 90.0]])
    assert out_of_plane_share(cells) == pytest.approx(2 / 5)
    assert not layout_takes_local_priors(cells)
    assert layout_takes_local_priors(cells[2:])  # 2 of 3


def test_pairs_in_the_plane_of_incidence_keep_the_library_prior() -> None:
    """The same specimen read by pairs all in the plane of incidence: however strong the
    evidence, the fit keeps the library's prior (an instrument geometry)."""
    b = _folded()
    truth = _sharp_cousin()
    # Six in-plane geometries (light and sensor on either side of the normal, th + td < 90).
    cells = np.deg2rad([[0.0, 15.0, 0.0], [5.0, 30.0, 0.0], [10.0, 45.0, 0.0],
                        [20.0, 25.0, 0.0], [30.0, 40.0, 0.0], [45.0, 20.0, 0.0]])
    ph = np.deg2rad([0.0, 30.0, 60.0, 90.0, 120.0, 150.0])
    alpha = uniform_stage_angles(8)
    vals = simulate_samples(truth, cells, ph, alpha, noise=NoiseModel(0.01, seed=3))
    post = ScanPosterior(b, cells, ph, alpha, vals)
    assert choose_local_prior(post, b) is not None  # the evidence alone would lean
    rec = reconstruct(b, cells, ph, alpha, vals)
    assert rec.settings["local_prior"] is None
    assert rec.settings["local_prior_note"] == "most pairs read in the plane of incidence"
    np.testing.assert_array_equal(
        rec.table.values, reconstruct(b, cells, ph, alpha, vals, local=None).table.values)


def test_the_asymmetric_default_basis_keeps_its_library_prior() -> None:
    """The basis a specimen without twofold symmetry is fitted with (marked so by
    default_basis) does not lean on its folded-in tables, even when the evidence would; the
    same basis unmarked does."""
    b = _folded()
    marked = Basis(b.Q, b.S, b.f_med, b.mu, b.valid, b.eps, b.materials,
                   {**b.provenance, "asymmetric_library": True}, b.ph_prior, b.local_means,
                   b.local_names)
    cells, ph, alpha, vals = _scan(_sharp_cousin())
    assert reconstruct(b, cells, ph, alpha, vals).settings["local_prior"] == "sharp"
    kept = reconstruct(marked, cells, ph, alpha, vals).settings
    assert kept["local_prior"] is None
    assert kept["local_prior_note"] == "the asymmetric basis keeps its library prior"
