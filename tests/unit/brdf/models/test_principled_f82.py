"""OpenPBR's F82-tint metal Fresnel in gonio's principled model (issue 26).

Expected values are the OpenPBR specification's formula ("Metal"), written out here:
``F(mu) = S(mu) - b mu (1 - mu)^6``, ``S(mu) = F0 + (1 - F0)(1 - mu)^5`` (Schlick),
``b = (S(mu_bar) - F_bar) / (mu_bar (1 - mu_bar)^6)`` with ``mu_bar = 1/7`` and the edge
reflectance ``F_bar = specular_color x S(mu_bar)``.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from gonio.brdf.models.principled import (
    F82TintFresnel,
    Principled,
    PrincipledError,
    f82_tint_fresnel,
)

MU = np.array([0.0, 0.05, 1.0 / 7.0, 0.3, 0.5, 0.8, 1.0])


def spec_f82(f0: float, tint: float, mu: float) -> float:
    """The specification's formula for one channel, unclipped."""
    mu_bar = 1.0 / 7.0
    s = f0 + (1 - f0) * (1 - mu) ** 5
    s_bar = f0 + (1 - f0) * (1 - mu_bar) ** 5
    b = (s_bar - tint * s_bar) / (mu_bar * (1 - mu_bar) ** 6)
    return s - b * mu * (1 - mu) ** 6


def test_white_tint_is_schlicks_curve() -> None:
    f0 = (0.91, 0.92, 0.92)
    got = f82_tint_fresnel(f0, (1.0, 1.0, 1.0), MU)
    for c, f in enumerate(f0):
        schlick = [f + (1 - f) * (1 - m) ** 5 for m in MU]
        assert got[:, c] == pytest.approx(schlick, abs=1e-12)


def test_reflectance_at_mu_bar_is_tint_times_schlick() -> None:
    # 81.79 degrees: cos = 1/7; aluminium-like F0 with a blue-ish tint below 1
    f0, tint = (0.91, 0.92, 0.92), (0.85, 0.88, 0.93)
    assert math.degrees(math.acos(1 / 7)) == pytest.approx(81.79, abs=0.01)
    got = f82_tint_fresnel(f0, tint, np.array([1 / 7]))[0]
    for c in range(3):
        schlick_82 = f0[c] + (1 - f0[c]) * (6 / 7) ** 5
        assert got[c] == pytest.approx(tint[c] * schlick_82, abs=1e-12)


def test_curve_matches_the_specification_and_dips_before_grazing() -> None:
    f0, tint = (0.91, 0.6, 0.3), (0.8, 0.5, 1.0)
    got = f82_tint_fresnel(f0, tint, MU)
    for c in range(3):
        want = [min(1.0, max(0.0, spec_f82(f0[c], tint[c], m))) for m in MU]
        assert got[:, c] == pytest.approx(want, abs=1e-12)
    # normal incidence F0, grazing 1 (the correction vanishes at both ends)
    assert got[-1] == pytest.approx(f0)
    assert got[0] == pytest.approx((1.0, 1.0, 1.0))
    # a tint below 1 takes the curve below its normal-incidence value near 82 degrees
    assert got[2, 0] < f0[0]


def test_negative_values_are_clipped() -> None:
    # F0 = 0 with tint 0: the spec's curve goes below 0 for mu between 1/7 and 1
    assert spec_f82(0.0, 0.0, 0.4) < 0
    assert f82_tint_fresnel((0.0,), (0.0,), np.array([0.4]))[0, 0] == 0.0


def test_principled_metal_with_tint_renders_the_tinted_fresnel() -> None:
    """The model's ratio tinted / untinted at a geometry where ``wi.h = 1/7`` is the tint
    (the lobe's D and G are the same; a metal has no diffuse)."""
    tint = (0.7, 0.8, 0.95)
    plain = Principled((0.9, 0.85, 0.8), 1.0, 0.5, 0.3, 0.1, 20.0)
    tinted = Principled((0.9, 0.85, 0.8), 1.0, 0.5, 0.3, 0.1, 20.0, f82_tint=tint)
    theta = math.acos(1 / 7)  # wi and wo each at theta from h = normal
    wi = np.array([[math.sin(theta), 0.0, math.cos(theta)]])
    wo = np.array([[-math.sin(theta), 0.0, math.cos(theta)]])
    ratio = tinted.model().eval(wi, wo)[0] / plain.model().eval(wi, wo)[0]
    assert ratio == pytest.approx(tint, rel=1e-9)
    # and at normal incidence there is no change
    n = np.array([[0.0, 0.0, 1.0]])
    assert tinted.model().eval(n, n)[0] == pytest.approx(plain.model().eval(n, n)[0])


def test_tint_round_trips_and_bad_tints_are_refused() -> None:
    p = Principled((0.9, 0.85, 0.8), 1.0, 0.5, 0.3, 0.1, 20.0, f82_tint=(0.7, 0.8, 0.95))
    back = Principled.from_dict(p.as_dict())
    assert back.f82_tint == pytest.approx((0.7, 0.8, 0.95))
    assert Principled.from_dict(
        Principled((0.5, 0.5, 0.5), 0.0, 0.5, 0.2, 0.2, 0.0).as_dict()).f82_tint is None
    with pytest.raises(PrincipledError, match="f82_tint"):
        Principled((0.9, 0.85, 0.8), 1.0, 0.5, 0.3, 0.1, 20.0, f82_tint=(1.2, 0.8, 0.9))
    with pytest.raises(PrincipledError, match="f82_tint"):
        Principled((0.9, 0.85, 0.8), 1.0, 0.5, 0.3, 0.1, 20.0, f82_tint=(0.8,))
    with pytest.raises(PrincipledError, match="F82 tint"):
        F82TintFresnel((0.5,), (-0.1,))
