"""Tests of the resolvable-roughness bound (math.md 11)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from gonio.brdf.design.roughness import (
    RoughnessError,
    below_bound_warning,
    bound_angles,
    effective_samples,
    resolvable_degree,
    roughness_bound,
    roughness_threshold,
)


def test_bound_angles_count_a_half_turn_with_its_copies() -> None:
    np.testing.assert_allclose(np.rad2deg(bound_angles(4, 360.0)), [0, 90, 180, 270])
    np.testing.assert_allclose(np.rad2deg(bound_angles(4, 180.0)),
                               [0, 45, 90, 135, 180, 225, 270, 315])


def test_degree_is_below_sqrt_n_and_fits_the_sh_unknowns() -> None:
    for n in [0, 1, 3, 4, 8, 9, 15, 16, 99, 100, 1000.5]:
        lstar = resolvable_degree(n)
        assert (lstar + 1) ** 2 <= max(n, 1)
        assert lstar < math.sqrt(n) or lstar == 0
        assert (lstar + 2) ** 2 > n  # the largest such degree


def test_threshold_attenuates_degree_lstar_by_t() -> None:
    for lstar in (1, 4, 17):
        a = roughness_threshold(lstar, 0.5)
        assert math.exp(-((a * lstar) ** 2)) == pytest.approx(0.5)
    assert math.isinf(roughness_threshold(0))
    with pytest.raises(RoughnessError, match=r"\(0, 1\)"):
        roughness_threshold(3, 1.5)


def test_effective_samples_counts_distinct_half_vectors_in_the_cap() -> None:
    alpha = np.deg2rad(np.arange(8) * 45.0)
    # th = 0 pair: one half vector at every angle; th = 10 pair: 8 distinct ones;
    # th = 50 pair: outside a 30 deg cap.
    cells = np.deg2rad([[0.0, 20.0, 0.0], [10.0, 20.0, 0.0], [50.0, 20.0, 0.0]])
    n = effective_samples(cells, np.zeros(3), alpha, cap_deg=30.0)
    omega = 2 * math.pi * (1 - math.cos(math.radians(30.0)))
    assert n == pytest.approx(9 * 4 * math.pi / omega)


def test_more_rotations_resolve_smoother_lobes() -> None:
    cells = np.deg2rad([[5.0, 20.0, 0.0], [15.0, 30.0, 90.0], [25.0, 10.0, 45.0]])
    ph = np.zeros(3)
    few = roughness_bound(cells, ph, np.deg2rad(np.arange(4) * 90.0))
    many = roughness_bound(cells, ph, np.deg2rad(np.arange(24) * 15.0))
    assert many.n_effective > few.n_effective
    assert many.alpha_min < few.alpha_min
    assert many.degree == resolvable_degree(many.n_effective)


def test_warning_only_below_the_bound() -> None:
    cells = np.deg2rad([[10.0, 20.0, 0.0]])
    b = roughness_bound(cells, np.zeros(1), np.deg2rad(np.arange(8) * 45.0))
    assert below_bound_warning(b.alpha_min * 1.01, b) is None
    msg = below_bound_warning(b.alpha_min * 0.5, b)
    assert msg is not None and "below the resolvable bound" in msg


@pytest.mark.parametrize(
    ("cells", "ph", "alpha", "cap", "match"),
    [
        (np.zeros((0, 3)), np.zeros(0), np.zeros(3), 30.0, "at least one pair"),
        (np.zeros((2, 3)), np.zeros(3), np.zeros(3), 30.0, "one per pair"),
        (np.zeros((1, 3)), np.zeros(1), np.zeros(3), 0.0, "specular cap"),
    ],
)
def test_bad_inputs(cells: np.ndarray, ph: np.ndarray, alpha: np.ndarray, cap: float,
                    match: str) -> None:
    with pytest.raises(RoughnessError, match=match):
        effective_samples(cells, ph, alpha, cap)
