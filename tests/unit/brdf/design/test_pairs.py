"""Tests of pair designs that can be mounted (gonio.brdf.design.pairs)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gonio.brdf.design.conditioning import (
    condition_number,
)
from gonio.brdf.design.pairs import PairDesign
from gonio.brdf.design.search import optimize_rows
from gonio.brdf.reconstruction.basis import Basis


def _grid_basis(K: int = 6) -> Basis:
    from gonio.brdf.tables import geometry as geo

    rng = np.random.default_rng(0)
    th, td, pd = (a.ravel() for a in geo.grid_angles())
    feats = np.stack([th, td, np.cos(2 * pd), np.sin(2 * pd)], axis=1)
    Q = np.cos(feats @ rng.normal(size=(4, K)) * 2.0 + rng.uniform(0, 6, size=K))
    return Basis(Q, np.ones(K), np.ones(geo.N_ROWS), np.zeros(geo.N_ROWS),
                 geo.valid_mask().ravel())


def test_design_pairs_places_the_optimized_cells() -> None:
    from gonio.brdf.design.constraints import RigConstraints
    from gonio.brdf.design.pairs import design_pairs

    basis = _grid_basis()
    d = design_pairs(basis, 4, RigConstraints(), h=3, starts=1, descents=1, seed=2,
                     objective="kappa")
    assert d.search is not None and d.kappa == pytest.approx(d.search.kappa)
    # The search's own statistics, none of the expected-error choice's.
    assert d.objective == "kappa" and d.greedy is None and d.fallback is None
    assert d.name == "optimized" and d.rotations == 8
    assert d.min_distance_deg >= 10.0 - 1e-6
    assert d.lab_deg.shape == (4, 4)


def _devices_of(design: PairDesign) -> np.ndarray:
    from gonio.brdf.tables import geometry as geo

    lab = np.deg2rad(design.lab_deg)
    wi = geo.spherical_to_direction(lab[:, 0], lab[:, 1])
    wo = geo.spherical_to_direction(lab[:, 2], lab[:, 3])
    return np.concatenate([wi, wo])


@settings(max_examples=12, deadline=None)
@given(seed=st.integers(0, 10_000), n=st.integers(2, 16),
       limit=st.sampled_from([8.0, 12.0, 18.0]))
def test_designs_under_a_device_distance_always_mount(seed: int, n: int, limit: float) -> None:
    from gonio.brdf.design.constraints import RigConstraints
    from gonio.brdf.design.pairs import design_pairs

    basis = _grid_basis(K=8)
    c = RigConstraints(max_elevation_deg=70.0, min_device_distance_deg=limit)
    d = design_pairs(basis, n, c, h=3, starts=1, descents=2, seed=seed, objective="kappa")
    _assert_mounted_as_reported(d, basis, n, limit)


@settings(max_examples=4, deadline=None)
@given(seed=st.integers(0, 10_000), n=st.integers(2, 10),
       limit=st.sampled_from([8.0, 12.0, 18.0]))
def test_expected_error_designs_under_a_device_distance_always_mount(
    seed: int, n: int, limit: float
) -> None:
    """The greedy choice mounts too, or hands over to the search (fewer, smaller examples:
    each greedy step checks placements)."""
    from gonio.brdf.design.constraints import RigConstraints
    from gonio.brdf.design.pairs import design_pairs

    basis = _grid_basis(K=8)
    c = RigConstraints(max_elevation_deg=70.0, min_device_distance_deg=limit)
    d = design_pairs(basis, n, c, h=3, starts=1, descents=2, seed=seed, objective="posterior")
    assert d.objective == "posterior" or d.fallback is not None
    _assert_mounted_as_reported(d, basis, n, limit)


def _assert_mounted_as_reported(d: PairDesign, basis: Basis, n: int, limit: float) -> None:
    from gonio.brdf.design.constraints import min_pairwise_distance
    from gonio.brdf.tables import geometry as geo

    dev = _devices_of(d)
    # Checked from the written lab directions, not from the design's own report.
    assert np.degrees(min_pairwise_distance(dev)) >= limit - 1e-6
    assert d.min_distance_deg >= limit - 1e-6
    assert (np.degrees(np.arccos(np.clip(dev[:, 2], -1, 1))) <= 70.0 + 1e-6).all()
    # The lab directions measure exactly the optimized cells (pd is defined mod pi), so the
    # geometry read back from them has the reported kappa.
    th, _, td, pd = geo.directions_to_half_diff(dev[:n], dev[n:])
    np.testing.assert_allclose(th, d.cells[:, 0], atol=1e-9)
    np.testing.assert_allclose(td, d.cells[:, 1], atol=1e-9)
    np.testing.assert_allclose(np.sin(2.0 * (pd - d.cells[:, 2])), 0.0, atol=1e-9)
    assert d.kappa == pytest.approx(condition_number(basis.Q[_rows_of(d.cells)]))
    assert d.kappa == pytest.approx(condition_number(basis.rows_at(th, td, pd)), rel=1e-6)


def _rows_of(cells: np.ndarray) -> np.ndarray:
    from gonio.brdf.tables import geometry as geo

    idx = [np.rint((cells[:, k] - g[0]) / (g[1] - g[0])).astype(int)
           for k, g in enumerate((geo.TH_GRID, geo.TD_GRID, geo.PD_GRID))]
    return np.ravel_multi_index(tuple(idx), geo.SLICE_SHAPE)


@pytest.mark.parametrize("objective", ["kappa", "posterior"])
def test_design_that_cannot_be_mounted_is_a_clear_error(objective: str) -> None:
    from gonio.brdf.design.constraints import RigConstraints
    from gonio.brdf.design.errors import FeasibilityError
    from gonio.brdf.design.pairs import design_pairs

    crowded = RigConstraints(max_elevation_deg=20.0, min_device_distance_deg=15.0)
    with pytest.raises(FeasibilityError,
                       match=r"cannot mount 12 pairs.*lower min_device_distance_deg"):
        design_pairs(_grid_basis(), 12, crowded, h=3, starts=1, descents=1,
                     objective=objective)  # type: ignore[arg-type]


@pytest.fixture(scope="module")
def library_basis() -> Basis:
    """K = 16 basis of one library material per family (built in ~2 s)."""
    from gonio.brdf.materials.library import library_specs
    from gonio.brdf.models import analytic as bm
    from gonio.brdf.reconstruction.basis import build_basis

    first: dict[str, bm.BRDFModel] = {}
    for spec in library_specs():
        first.setdefault(spec.family, spec.model)
    return build_basis([bm.tabulate(m) for m in first.values()], 16)


def test_twenty_pairs_mount_with_default_limits_on_a_library_basis(library_basis: Basis) -> None:
    from gonio.brdf.design.constraints import (
        RigConstraints,
        candidate_rows,
        min_pairwise_distance,
        rows_to_cells,
    )
    from gonio.brdf.design.errors import FeasibilityError
    from gonio.brdf.design.pairs import design_pairs
    from gonio.brdf.design.placement import place_pairs

    c = RigConstraints()  # 80 deg elevation, 10 deg separation, 10 deg between devices
    # The failure this guards against: a cells-only search crowds pairs near the zenith, so
    # its designs mostly cannot be mounted (4 of seeds 0-4 when this was written).
    cand = candidate_rows(c, library_basis.valid)
    collided, blind_kappas = 0, []
    for seed in (1, 2, 3):
        blind = optimize_rows(library_basis.Q, cand, 20, starts=1, descents=2, seed=seed)
        blind_kappas.append(blind.kappa)
        try:
            place_pairs(rows_to_cells(blind.rows), c, orderings=4)
        except FeasibilityError as exc:
            assert "cannot mount 20 pairs" in str(exc)
            collided += 1
    assert collided >= 1
    d = design_pairs(library_basis, 20, c, starts=1, descents=2, seed=1, objective="kappa")
    assert d.n_pairs == 20 and np.isfinite(d.kappa)
    assert np.degrees(min_pairwise_distance(_devices_of(d))) >= 10.0 - 1e-6
    # Collision-awareness costs little conditioning against the blind search.
    assert d.kappa < 2.0 * float(np.median(blind_kappas))


def test_a_crowded_rig_falls_back_to_the_search_that_plans_mounts(
    library_basis: Basis, caplog: pytest.LogCaptureFixture
) -> None:
    """Seven pairs within 55 deg of the normal, devices 25 deg apart: the expected-error greedy
    paints itself into a corner (no mountable cell for the last pair), the kappa search mounts
    them."""
    import logging

    from gonio.brdf.design.constraints import RigConstraints, min_pairwise_distance
    from gonio.brdf.design.errors import FeasibilityError
    from gonio.brdf.design.pairs import design_pairs
    from gonio.brdf.design.posterior import posterior_design

    c = RigConstraints(max_elevation_deg=55.0, min_device_distance_deg=25.0)
    with pytest.raises(FeasibilityError, match="no mountable cell"):
        posterior_design(library_basis, 7, c)
    with caplog.at_level(logging.WARNING, logger="gonio.brdf.design.pairs"):
        d = design_pairs(library_basis, 7, c, starts=1, descents=2, objective="posterior")
    assert d.objective == "kappa" and d.search is not None and d.greedy is None
    assert d.fallback is not None and "could not be mounted" in d.fallback
    assert "no mountable cell" in d.fallback and d.fallback in caplog.text
    # Worded for a caller: the advice's setting names replaced, the rest kept.
    worded = d.fallback_for({"min_device_distance_deg": "--min-device-distance"})
    assert worded == d.fallback.replace("min_device_distance_deg", "--min-device-distance")
    assert worded != d.fallback
    dev = _devices_of(d)
    assert np.degrees(min_pairwise_distance(dev)) >= 25.0 - 1e-6
    assert (np.degrees(np.arccos(np.clip(dev[:, 2], -1, 1))) <= 55.0 + 1e-6).all()
    # The report stays complete: kappa of the rows and the expected error at 8 rotations.
    assert d.kappa == pytest.approx(condition_number(library_basis.Q[_rows_of(d.cells)]))
    assert d.expected_log_rmse is not None and d.expected_log_rmse > 0


@pytest.mark.parametrize("default", ["kappa", "posterior"])
def test_design_pairs_uses_the_module_default_objective(
    default: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    from gonio.brdf.design import pairs
    from gonio.brdf.design.constraints import RigConstraints
    from gonio.brdf.design.posterior import design_expected_log_rmse, prior_model

    monkeypatch.setattr(pairs, "DEFAULT_OBJECTIVE", default)
    basis = _grid_basis()
    d = pairs.design_pairs(basis, 5, RigConstraints(), h=3, starts=1, descents=1)
    assert d.objective == default and d.fallback is None
    assert (d.search is not None) == (default == "kappa")
    assert (d.greedy is not None) == (default == "posterior")
    # Whichever objective chose the rows, the report carries both numbers for them.
    rows = basis.Q[_rows_of(d.cells)]
    assert d.kappa == pytest.approx(condition_number(rows))
    want = design_expected_log_rmse(prior_model(basis, 8), rows)
    assert d.expected_log_rmse == pytest.approx(want)


def test_a_default_posterior_objective_falls_back_for_rows_without_a_basis(
    monkeypatch: pytest.MonkeyPatch
) -> None:
    """``design_pairs(basis, n, constraints)`` keeps working for any row source; only an
    explicit ``objective="posterior"`` insists on a gonio Basis."""
    from gonio.brdf.design import pairs
    from gonio.brdf.design.constraints import RigConstraints
    from gonio.brdf.design.errors import DesignError
    from gonio.brdf.tables import geometry as geo

    class RowsOnly:
        def __init__(self, b: Basis) -> None:
            self.Q, self.valid, self.rows_at = b.Q, b.valid, b.rows_at

    rows_only = RowsOnly(_grid_basis())
    monkeypatch.setattr(pairs, "DEFAULT_OBJECTIVE", "posterior")
    d = pairs.design_pairs(rows_only, 3, RigConstraints(), h=3, starts=1, descents=1)
    assert d.objective == "kappa" and d.expected_log_rmse is None
    assert d.fallback is not None and "needs a gonio Basis" in d.fallback
    with pytest.raises(DesignError, match="needs a gonio Basis"):
        pairs.design_pairs(rows_only, 3, RigConstraints(), objective="posterior")
    with pytest.raises(DesignError, match="rotations=0"):
        pairs.design_pairs(rows_only, 3, RigConstraints(), rotations=0)
    # a cell weighting is refused, as colour is, rather than dropped by the kappa fallback
    with pytest.raises(DesignError, match=r"cell weighting \(cell_mix > 0\) needs a gonio Basis"):
        pairs.design_pairs(rows_only, 3, RigConstraints(), h=3, starts=1, descents=1,
                           cell_weight=np.ones(geo.SLICE_SHAPE), cell_mix=0.5)


def test_an_expected_error_choice_past_its_time_limit_hands_over_to_the_search(
    library_basis: Basis,
) -> None:
    """The API's time limit holds for both objectives: a choice that cannot finish its mount
    checks in time gives way to the search (with a time limit of its own), and says so."""
    from gonio.brdf.design.constraints import RigConstraints, min_pairwise_distance
    from gonio.brdf.design.errors import DesignTimeout
    from gonio.brdf.design.pairs import design_pairs
    from gonio.brdf.design.posterior import posterior_design

    c = RigConstraints()
    with pytest.raises(DesignTimeout,
                       match=r"did not finish within 1e-06 s of CPU time \(at pair 1 of 12"):
        posterior_design(library_basis, 12, c, time_limit_s=1e-6)
    d = design_pairs(library_basis, 12, c, starts=1, descents=1, objective="posterior",
                     time_limit_s=1e-6)
    assert d.objective == "kappa" and d.search is not None and d.greedy is None
    assert d.fallback is not None and "did not finish within 1e-06 s" in d.fallback
    assert np.degrees(min_pairwise_distance(_devices_of(d))) >= 10.0 - 1e-6


def test_the_default_design_weighs_the_cells_the_renderings_see(library_basis: Basis) -> None:
    """``design_pairs(basis, n, constraints)`` is the expected-error design with the standard
    renderings' pixel counts mixed in at one half (docs/science.md 7.2.2): the same pairs as
    the core asked for that weighting, with the map counted by the renderer itself (not the
    shipped copy), and other pairs than the unweighted design; ``cell_mix=0`` is that
    unweighted design."""
    from gonio.brdf.design.constraints import RigConstraints
    from gonio.brdf.design.pairs import design_pairs
    from gonio.brdf.design.posterior import posterior_design
    from gonio.brdf.pictures.appearance import render_importance

    c = RigConstraints()
    d = design_pairs(library_basis, 6, c)
    assert d.objective == "posterior" and d.fallback is None and d.cell_mix == 0.5
    weighted = posterior_design(library_basis, 6, c, cell_weight=render_importance(),
                                cell_mix=0.5)
    np.testing.assert_allclose(d.cells, weighted.cells)
    plain = design_pairs(library_basis, 6, c, cell_mix=0.0)
    assert plain.cell_mix == 0.0
    np.testing.assert_allclose(plain.cells, posterior_design(library_basis, 6, c).cells)
    assert not np.allclose(np.sort(plain.cells, axis=0), np.sort(d.cells, axis=0))
    # The condition-number search takes no weighting.
    assert design_pairs(library_basis, 4, c, objective="kappa", starts=1,
                        descents=1).cell_mix == 0.0


def test_an_explicit_weighting_on_a_crowded_rig_fails_and_says_how_the_default_falls_back(
        library_basis: Basis) -> None:
    """The crowded rig above: the default weighting falls back to the search, a weighting
    asked for explicitly is not dropped silently; its error names the way out."""
    from gonio.brdf.design.constraints import RigConstraints
    from gonio.brdf.design.errors import FeasibilityError
    from gonio.brdf.design.pairs import design_pairs
    from gonio.brdf.design.renderweight import render_weight

    c = RigConstraints(max_elevation_deg=55.0, min_device_distance_deg=25.0)
    with pytest.raises(FeasibilityError) as exc:
        design_pairs(library_basis, 7, c, cell_weight=render_weight(), cell_mix=0.5)
    assert "no mountable cell" in str(exc.value)
    assert "or leave the cell weighting (cell_mix; the API's render_mix) out" in str(exc.value)
    # The CLI words the knobs as its flags.
    assert "or leave --render-mix out" in exc.value.advise({"cell_mix": "--render-mix"})
    assert design_pairs(library_basis, 7, c, starts=1, descents=2).objective == "kappa"


def test_a_condition_number_design_does_not_read_the_renderings_map(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """The default weighting is the expected-error design's: a kappa design never needs the
    shipped map (so an install that lost it can still make one)."""
    from gonio.brdf.design import pairs
    from gonio.brdf.design.constraints import RigConstraints

    def missing() -> None:
        raise AssertionError("the map was read")

    monkeypatch.setattr(pairs, "render_weight", missing)
    d = pairs.design_pairs(_grid_basis(), 4, RigConstraints(), h=3, starts=1, descents=1,
                           objective="kappa")
    assert d.objective == "kappa" and d.cell_mix == 0.0
