"""Properties of the half/difference parameterization and the 5 degree grid."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gonio.brdf.tables import geometry as geo

DEG = np.pi / 180
angle_th = st.floats(0.5 * DEG, 89.0 * DEG)
angle_td = st.floats(0.5 * DEG, 89.0 * DEG)
angle_ph = st.floats(0.0, 2 * np.pi, exclude_max=True)
angle_pd = st.floats(0.0, np.pi, exclude_max=True)
azimuth = st.floats(-10.0, 10.0)


def ang_diff(a: np.ndarray | float, b: np.ndarray | float, period: float) -> np.ndarray:
    """Smallest absolute difference of angles modulo ``period``."""
    d = np.mod(np.asarray(a) - np.asarray(b), period)
    return np.minimum(d, period - d)


def direction(theta: float, phi: float) -> np.ndarray:
    return geo.spherical_to_direction(theta, phi)


@settings(max_examples=200, deadline=None)
@given(angle_th, angle_ph, angle_td, angle_pd)
def test_forward_then_inverse_round_trip(th: float, ph: float, td: float, pd: float) -> None:
    wi, wo = geo.half_diff_to_directions(th, ph, td, pd)
    np.testing.assert_allclose(np.linalg.norm(wi), 1.0, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(wo), 1.0, atol=1e-12)
    th2, ph2, td2, pd2 = geo.directions_to_half_diff(wi, wo)
    assert abs(th2 - th) < 1e-9 and abs(td2 - td) < 1e-9
    assert ang_diff(ph2, ph, 2 * np.pi) < 1e-8
    assert ang_diff(pd2, pd, np.pi) < 1e-8


@settings(max_examples=200, deadline=None)
@given(st.floats(0.0, 1.5), azimuth, st.floats(0.0, 1.5), azimuth)
def test_inverse_then_forward_gives_the_pair_back(
    ti: float, pi_: float, to: float, po: float
) -> None:
    wi, wo = direction(ti, pi_), direction(to, po)
    back_i, back_o = geo.half_diff_to_directions(*geo.directions_to_half_diff(wi, wo))
    # pd is folded into [0, pi): the forward map may return the pair swapped (reciprocity).
    same = np.allclose(back_i, wi, atol=1e-7) and np.allclose(back_o, wo, atol=1e-7)
    swapped = np.allclose(back_i, wo, atol=1e-7) and np.allclose(back_o, wi, atol=1e-7)
    assert same or swapped


@settings(max_examples=200, deadline=None)
@given(angle_th, angle_ph, angle_td, angle_pd)
def test_swapping_light_and_view_is_pd_plus_pi(th: float, ph: float, td: float, pd: float) -> None:
    wi, wo = geo.half_diff_to_directions(th, ph, td, pd)
    swapped_i, swapped_o = geo.half_diff_to_directions(th, ph, td, pd + np.pi)
    np.testing.assert_allclose(swapped_i, wo, atol=1e-12)
    np.testing.assert_allclose(swapped_o, wi, atol=1e-12)
    a = geo.directions_to_half_diff(wi, wo)
    b = geo.directions_to_half_diff(wo, wi)
    assert abs(a[0] - b[0]) < 1e-9 and abs(a[2] - b[2]) < 1e-9
    assert ang_diff(a[1], b[1], 2 * np.pi) < 1e-8
    assert ang_diff(a[3], b[3], np.pi) < 1e-8  # same pd cell


@settings(max_examples=200, deadline=None)
@given(st.floats(0.05, 1.5), azimuth, st.floats(0.05, 1.5), azimuth, st.floats(-7.0, 7.0))
def test_stage_rotation_shifts_only_ph(
    ti: float, pi_: float, to: float, po: float, alpha: float
) -> None:
    wi, wo = direction(ti, pi_), direction(to, po)
    lab = geo.directions_to_half_diff(wi, wo)
    spec = geo.directions_to_half_diff(
        geo.lab_to_specimen(wi, alpha), geo.lab_to_specimen(wo, alpha)
    )
    # arccos loses precision near 0 (about 1e-8 rad), hence the looser tolerance.
    assert abs(lab[0] - spec[0]) < 1e-7 and abs(lab[2] - spec[2]) < 1e-7
    # At th = 0 the half vector is the normal: ph is undefined (set to 0) and the turn moves
    # into pd instead; everywhere else only ph changes.
    if lab[0] > 1e-6 and lab[2] > 1e-6:
        assert ang_diff(lab[3], spec[3], np.pi) < 1e-7
        assert ang_diff(spec[1], geo.stage_shifted_ph(lab[1], alpha), 2 * np.pi) < 1e-8


@given(st.floats(-7.0, 7.0), st.floats(0.0, 1.5), azimuth)
def test_lab_to_specimen_keeps_elevation_and_turns_azimuth_back(
    alpha: float, theta: float, phi: float
) -> None:
    v = direction(theta, phi)
    w = geo.lab_to_specimen(v, alpha)
    assert w[2] == v[2]  # a turn about the normal keeps the elevation exactly
    np.testing.assert_allclose(np.linalg.norm(w), 1.0, atol=1e-12)
    if theta > 1e-6:  # the azimuth of the normal itself is undefined
        assert ang_diff(geo.direction_to_spherical(w)[1], phi - alpha, 2 * np.pi) < 1e-8


def test_grid_constants() -> None:
    assert geo.TH_GRID.shape == (18,) and geo.PD_GRID.shape == (36,) and geo.PH_GRID.shape == (72,)
    assert geo.N_ROWS == 18 * 18 * 36 == 11664
    np.testing.assert_allclose(np.rad2deg(geo.PD_GRID[-1]), 175.0)
    np.testing.assert_allclose(np.rad2deg(geo.PH_GRID[-1]), 355.0)


def test_valid_mask_matches_directions_and_is_mirror_symmetric() -> None:
    mask = geo.valid_mask()
    th, td, pd = geo.grid_angles()
    wi, wo = geo.half_diff_to_directions(th, 0.0, td, pd)
    np.testing.assert_array_equal(mask, (wi[..., 2] > 1e-9) & (wo[..., 2] > 1e-9))
    # pd -> pi - pd swaps the light and view elevations, so validity cannot change.
    mirrored = mask[:, :, (-np.arange(geo.N_PD)) % geo.N_PD]
    np.testing.assert_array_equal(mask, mirrored)
    assert mask[0].all()  # at th = 0 every cell is valid (td <= 85 degrees)
    assert 0 < mask.sum() < mask.size


def test_volume_weight_is_positive_and_integrates_the_domain() -> None:
    w = geo.volume_weight()
    assert w.shape == geo.SLICE_SHAPE and (w > 0).all()
    # Cells reach 87.5 degrees (centres up to 85 plus half a step); over all 72 ph slices the
    # weight integrates 4 cos td sin td sin th on [0, 87.5]^2 times 2 pi (ph) and pi (pd).
    top = 87.5 * DEG
    analytic = (1 - np.cos(top)) * 2 * np.sin(top) ** 2 * 2 * np.pi * np.pi
    np.testing.assert_allclose(w.sum() * geo.N_PH, analytic, rtol=1e-12)
    assert w[0].sum() > 0  # th = 0 row keeps weight
    # Independent of pd, increasing with th on the lower half of the range.
    np.testing.assert_allclose(w, np.broadcast_to(w[:, :, :1], w.shape))
    assert (np.diff(w[:, 5, 0]) > 0).all()


def test_remap_weight_floor() -> None:
    w = geo.remap_weight(eps=1e-3)
    ci, co = geo.cell_cosines(*geo.grid_angles())
    np.testing.assert_allclose(w, np.maximum(ci * co, 1e-3))
    assert w.min() == 1e-3


@given(st.integers(0, 17), st.integers(0, 17), st.integers(0, 35))
def test_flat_row_is_c_order(i_th: int, i_td: int, i_pd: int) -> None:
    row = int(geo.flat_row(i_th, i_td, i_pd))
    assert row == (i_th * 18 + i_td) * 36 + i_pd
    assert 0 <= row < geo.N_ROWS


def test_cell_cosines_match_directions() -> None:
    th, td, pd = geo.grid_angles()
    ci, co = geo.cell_cosines(th, td, pd)
    wi, wo = geo.half_diff_to_directions(th, 1.234, td, pd)
    np.testing.assert_allclose(ci, wi[..., 2], atol=1e-12)
    np.testing.assert_allclose(co, wo[..., 2], atol=1e-12)


@pytest.mark.parametrize("theta", [1e-9, 3e-7, 1e-4])
def test_angles_near_the_normal_keep_full_precision(theta: float) -> None:
    # arccos(z) would lose about half the digits here (error ~ sqrt(eps) ~ 1e-8 rad); a design
    # whose device sits near the zenith must read back the cell it was optimized for.
    w = geo.spherical_to_direction(theta, 1.0)
    t, _ = geo.direction_to_spherical(w)
    assert t == pytest.approx(theta, rel=1e-12)
    wi, wo = geo.half_diff_to_directions(theta, 0.5, 0.3, 1.0)
    th, _, td, _ = geo.directions_to_half_diff(wi, wo)
    assert th == pytest.approx(theta, rel=1e-9)
    assert td == pytest.approx(0.3, rel=1e-12)
