"""The colour design: pairs at the near-specular instrument geometries, the rest weighted toward
the other targets (gonio.brdf.design.colourtargets, posterior_design(colour=...))."""

from __future__ import annotations

import math

import numpy as np
import pytest

from gonio.brdf.design.colourtargets import ColourTargets
from gonio.brdf.design.constraints import RigConstraints
from gonio.brdf.design.errors import DesignError
from gonio.brdf.design.pairs import design_pairs
from gonio.brdf.design.posterior import _posterior, posterior_design, prior_model
from gonio.brdf.tables import geometry as geo
from tests.unit.brdf.reconstruction.test_reconstruct import random_basis
from tests.unit.brdf.reconstruction.test_reconstruct_joint import _with_prior

# MA98's in-plane geometries (incidence, aspecular), X-Rite's published set.
MA98 = ((45, -15), (45, 15), (45, 25), (45, 45), (45, 75), (45, 110),
        (15, -45), (15, -15), (15, -5), (15, 45), (15, 80))


def in_plane(incidence: float, aspecular: float) -> tuple[np.ndarray, np.ndarray]:
    """Light and sensor in the x-z plane: the sensor at ``aspecular`` from the mirror direction,
    toward the light (ASTM E2194)."""
    ti, tv = math.radians(incidence), math.radians(incidence - aspecular)
    return (np.array([math.sin(ti), 0.0, math.cos(ti)]),
            np.array([-math.sin(tv), 0.0, math.cos(tv)]))


def targets(**kw: float) -> ColourTargets:
    pairs = [in_plane(i, a) for i, a in MA98]
    return ColourTargets(np.stack([p[0] for p in pairs]), np.stack([p[1] for p in pairs]),
                         **kw)


def basis() -> object:
    return _with_prior(random_basis(6), {0: 1.0, 2: 0.5})


def test_near_specular_geometries_become_the_first_pairs() -> None:
    """The half vector of an in-plane geometry sits at half its aspecular angle from the
    normal, and half the light-sensor angle is ``(2 incidence - aspecular) / 2``: aspecular
    angles up to 25 degrees (half vector within 12.5) get pairs at exactly those angles."""
    d = posterior_design(basis(), 8, RigConstraints(), colour=targets())  # type: ignore[arg-type]
    near = [(i, a) for i, a in MA98 if abs(a) <= 25]
    assert d.colour_pairs == len(near) == 5
    want = sorted((abs(a) / 2, (2 * i - a) / 2) for i, a in near)
    got = sorted(tuple(np.round(np.rad2deg(c[:2]), 9)) for c in d.cells[:5])
    np.testing.assert_allclose(got, want, atol=1e-9)
    # The lab placement measures those cells: the pairs' devices give them back.
    wi, _wo = geo.half_diff_to_directions(d.cells[:, 0], d.ph_lab, d.cells[:, 1], d.cells[:, 2])
    light = np.deg2rad(d.lab_deg[:, :2])
    li = np.stack([np.sin(light[:, 0]) * np.cos(light[:, 1]),
                   np.sin(light[:, 0]) * np.sin(light[:, 1]), np.cos(light[:, 0])], axis=1)
    np.testing.assert_allclose(li, wi, atol=1e-9)
    assert d.min_distance_deg >= RigConstraints().min_device_distance_deg - 1e-6
    # The other three are distinct grid cells.
    rest = np.rint(np.rad2deg(d.cells[5:]) / 5.0)
    assert len({tuple(r) for r in rest}) == 3
    np.testing.assert_allclose(np.rad2deg(d.cells[5:]), 5.0 * rest, atol=1e-9)
    assert d.expected_log_rmse is not None and math.isfinite(d.expected_log_rmse)


def test_the_weight_lowers_the_expected_error_at_the_targets() -> None:
    """With the direct pairs alone (weight 0) the other pairs ignore the far targets; a large
    weight spends them there: the posterior variance at the targets' rows (Woodbury, from the
    prior and the chosen rows) is lower."""
    b = basis()
    t0, t1 = targets(weight=0.0), targets(weight=100.0)
    model = prior_model(b)  # type: ignore[arg-type]
    cells, _ph = t0.cells()
    q_t = b.rows_at(cells[:, 0], cells[:, 1], cells[:, 2])  # type: ignore[attr-defined]

    def target_variance(weight_design: object) -> float:
        c = weight_design.cells  # type: ignore[attr-defined]
        q = b.rows_at(c[:, 0], c[:, 1], c[:, 2])  # type: ignore[attr-defined]
        total = 0.0
        for P, s in zip(model.P, model.noise, strict=True):
            total += float(np.trace(q_t @ _posterior(P, q, s) @ q_t.T))
        return total

    d0 = posterior_design(b, 9, RigConstraints(), colour=t0)  # type: ignore[arg-type]
    d1 = posterior_design(b, 9, RigConstraints(), colour=t1)  # type: ignore[arg-type]
    assert d0.colour_pairs == d1.colour_pairs == 5
    assert target_variance(d1) < target_variance(d0)


def test_without_colour_the_design_is_unchanged() -> None:
    b = basis()
    plain = posterior_design(b, 5, RigConstraints())  # type: ignore[arg-type]
    none = posterior_design(b, 5, RigConstraints(), colour=None)  # type: ignore[arg-type]
    np.testing.assert_array_equal(plain.cells, none.cells)
    assert plain.colour_pairs == 0


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [({"weight": -1.0}, "weight must be a number >= 0"),
     ({"weight": float("nan")}, "weight must be a number >= 0"),
     ({"direct_within_deg": 95.0}, "direct_within_deg must be in 0..90")],
)
def test_bad_colour_settings_are_refused(kwargs: dict, match: str) -> None:
    with pytest.raises(DesignError, match=match):
        targets(**kwargs)


def test_bad_directions_are_refused() -> None:
    with pytest.raises(DesignError, match="same shape"):
        ColourTargets(np.zeros((2, 3)), np.zeros((3, 3)))
    with pytest.raises(DesignError, match="unit vectors"):
        ColourTargets(np.ones((1, 3)), np.ones((1, 3)))
    with pytest.raises(DesignError, match="above the specimen"):
        ColourTargets(np.array([[0.0, 0.0, -1.0]]), np.array([[0.0, 0.0, 1.0]]))


def test_too_few_pairs_for_the_direct_geometries_is_an_error() -> None:
    with pytest.raises(DesignError, match=r"need 5 pairs of their own.*at least 5 pairs"):
        posterior_design(basis(), 4, RigConstraints(), colour=targets())  # type: ignore[arg-type]
    # Fewer direct geometries (aspecular up to 10 degrees: only 15as-5) fit in 4 pairs.
    d = posterior_design(basis(), 4, RigConstraints(),  # type: ignore[arg-type]
                         colour=targets(direct_within_deg=5.0))
    assert d.colour_pairs == 1
    np.testing.assert_allclose(np.rad2deg(d.cells[0, :2]), [2.5, 17.5], atol=1e-9)


def test_design_pairs_takes_colour_only_with_the_expected_error_objective() -> None:
    b = basis()
    via = design_pairs(b, 6, RigConstraints(), colour=targets())  # type: ignore[arg-type]
    assert via.objective == "posterior" and via.colour_pairs == 5
    with pytest.raises(DesignError, match="expected-error design only"):
        design_pairs(b, 6, RigConstraints(), objective="kappa",  # type: ignore[arg-type]
                     colour=targets())
