"""The simulated reading: geometry of the stage rotation, the signal chain and its noise."""

from __future__ import annotations

import math

import numpy as np
import pytest
from numpy.typing import ArrayLike, NDArray

from gonio.brdf.models.analytic import Lambert
from gonio.hal import LabDirection
from gonio.sim.specimen import (
    NoiseModel,
    Specimen,
    brdf_from_counts,
    expected_counts,
    sample_counts,
)


class _SpecimenX:
    """A probe 'BRDF' equal to the specimen-frame x component of the light direction."""

    def eval(self, wi: ArrayLike, wo: ArrayLike) -> NDArray[np.float64]:
        return np.asarray(wi, dtype=float)[..., 0:1]


def _vec(theta: float, phi: float) -> NDArray[np.float64]:
    return np.asarray(LabDirection(theta, phi).vector())


def test_stage_rotation_turns_lab_directions_into_the_specimen_frame() -> None:
    spec = Specimen(_SpecimenX())
    wi = _vec(60.0, 90.0)  # light along lab +y
    wo = _vec(30.0, 0.0)
    # At stage 0 the specimen x axis is lab x: the light has no x component.
    assert spec.brdf_lab(wi, wo, 0.0)[0] == pytest.approx(0.0, abs=1e-12)
    # Turning the specimen by +90 deg brings its x axis under lab +y (math.md 1).
    assert spec.brdf_lab(wi, wo, 90.0)[0] == pytest.approx(math.sin(math.radians(60.0)))
    # Negative probe values are clamped: a BRDF is never negative.
    assert spec.brdf_lab(wi, wo, 270.0)[0] == 0.0


def test_lambert_signal_and_its_inversion() -> None:
    albedo = (0.2, 0.5, 0.8)
    spec = Specimen(Lambert(albedo))
    wi, wo = _vec(40.0, 10.0), _vec(55.0, 200.0)
    E, gain, t = 3.0e5, 2.0, 0.05
    counts = expected_counts(spec, [(wi, E)], wo, stage_deg=123.0, gain=gain, exposure_s=t)
    expect = E * np.array(albedo) / math.pi * math.cos(math.radians(40.0)) * gain * t
    np.testing.assert_allclose(counts, expect, rtol=1e-12)
    back = brdf_from_counts(counts, 0.0, E, wi, gain, t)
    np.testing.assert_allclose(back, np.array(albedo) / math.pi, rtol=1e-12)


def test_two_lamps_add_and_a_lamp_below_the_horizon_adds_nothing() -> None:
    spec = Specimen(Lambert(0.5))
    wo = _vec(30.0, 0.0)
    one = expected_counts(spec, [(_vec(20.0, 0.0), 1e4)], wo, 0.0, 1.0, 1.0)
    two = expected_counts(
        spec, [(_vec(20.0, 0.0), 1e4), (_vec(20.0, 90.0), 1e4)], wo, 0.0, 1.0, 1.0
    )
    np.testing.assert_allclose(two, 2 * one)
    below = np.array([1.0, 0.0, -0.1]) / np.linalg.norm([1.0, 0.0, -0.1])
    assert np.all(expected_counts(spec, [(below, 1e4)], wo, 0.0, 1.0, 1.0) == 0.0)


def test_noise_statistics_follow_the_model() -> None:
    noise = NoiseModel(dark_offset=100.0, dark_rate=40.0, read_noise=3.0, shot_gain=0.5)
    signal = np.array([0.0, 1000.0, 20000.0])
    t = 0.5
    rng = np.random.default_rng(7)
    samples = np.array([sample_counts(signal, t, noise, rng) for _ in range(4000)])
    mean_expect = signal + 100.0 + 40.0 * t
    sigma_expect = np.sqrt(0.5 * (signal + 40.0 * t) + 9.0)
    # 5 standard errors of the mean; rounding to whole counts adds 1/12 count^2 of variance.
    np.testing.assert_allclose(samples.mean(0), mean_expect, atol=5 * sigma_expect.max() / 63)
    np.testing.assert_allclose(samples.std(0), np.sqrt(sigma_expect**2 + 1 / 12), rtol=0.06)
    assert np.all(samples == np.rint(samples))


def test_seeded_noise_is_reproducible() -> None:
    noise = NoiseModel()
    a = sample_counts([500.0, 600.0], 0.1, noise, np.random.default_rng(3))
    b = sample_counts([500.0, 600.0], 0.1, noise, np.random.default_rng(3))
    c = sample_counts([500.0, 600.0], 0.1, noise, np.random.default_rng(4))
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)


def test_readings_clip_at_saturation() -> None:
    noise = NoiseModel(saturation=4095.0)
    out = sample_counts([1e6, 10.0], 0.01, noise, np.random.default_rng(0))
    assert out[0] == 4095.0 and out[1] < 4095.0


def test_inversion_refuses_a_light_below_the_horizon() -> None:
    with pytest.raises(ValueError, match="below the horizon"):
        brdf_from_counts([1.0], 0.0, 1.0, [1.0, 0.0, 0.0], 1.0, 1.0)
