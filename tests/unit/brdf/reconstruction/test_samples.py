"""Tests of sample simulation, the noise model and the samples file."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from gonio.brdf.reconstruction.samples import (
    NoiseModel,
    Samples,
    SamplesError,
    pair_directions,
    simulate_samples,
    span_periods,
    uniform_stage_angles,
)
from gonio.brdf.tables import geometry as geo
from tests.unit.brdf.reconstruction.test_basis import small_library, ward_like


class Analytic:
    """An analytic specimen with ``eval``: the simulation must work on any such object."""

    def __init__(self) -> None:
        self.fn = ward_like((0.2, 0.4, 0.6), 0.5, 0.1, 0.3, angle=0.4)

    def eval(self, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        return np.asarray(self.fn(np.asarray(wi), np.asarray(wo)))  # type: ignore[operator]


def test_noiseless_samples_are_the_brdf_at_the_rotated_directions() -> None:
    spec = Analytic()
    cells = np.deg2rad([[20.0, 30.0, 40.0], [0.0, 45.0, 90.0], [60.0, 10.0, 170.0]])
    ph = np.deg2rad([10.0, 100.0, 250.0])
    alpha = np.deg2rad([0.0, 33.0, 200.0, 359.0])
    vals = simulate_samples(spec, cells, ph, alpha, noise=NoiseModel(0.0, 0.0))
    assert vals.shape == (3, 4, 3)
    for q in range(3):
        for j in range(4):
            # The specimen sees slice ph_lab - alpha of the same (th, td, pd).
            wi, wo = geo.half_diff_to_directions(
                cells[q, 0], ph[q] - alpha[j], cells[q, 1], cells[q, 2]
            )
            np.testing.assert_allclose(vals[q, j], spec.eval(wi[None], wo[None])[0], rtol=1e-10)


def test_tables_can_be_sampled_and_grid_points_are_exact() -> None:
    table = small_library()[0]
    cells = np.stack([geo.TH_GRID[[3, 8]], geo.TD_GRID[[2, 5]], geo.PD_GRID[[10, 30]]], 1)
    ph = geo.PH_GRID[[4, 60]]
    alpha = geo.PH_GRID[[0, 9]]
    vals = simulate_samples(table, cells, ph, alpha, noise=NoiseModel(0, 0))
    expect = table.values[:, (4 - 0) % 72, 3, 2, 10]
    np.testing.assert_allclose(vals[0, 0], expect, rtol=1e-5)
    expect = table.values[:, (60 - 9) % 72, 8, 5, 30]
    np.testing.assert_allclose(vals[1, 1], expect, rtol=1e-5)


def test_noise_model_statistics_and_seed() -> None:
    spec = Analytic()
    cells = np.tile(np.deg2rad([[30.0, 20.0, 60.0]]), (200, 1))
    ph = np.zeros(200)
    alpha = uniform_stage_angles(50)
    clean = simulate_samples(spec, cells, ph, alpha, noise=NoiseModel(0, 0))
    noisy = simulate_samples(spec, cells, ph, alpha, noise=NoiseModel(0.05, seed=1))
    ratio = noisy / clean
    assert np.std(ratio) == pytest.approx(0.05, rel=0.05)
    assert abs(np.mean(ratio) - 1.0) < 0.005
    again = simulate_samples(spec, cells, ph, alpha, noise=NoiseModel(0.05, seed=1))
    np.testing.assert_array_equal(noisy, again)
    other = simulate_samples(spec, cells, ph, alpha, noise=NoiseModel(0.05, seed=2))
    assert not np.array_equal(noisy, other)
    # Absolute noise on a black specimen never goes negative.
    dark = NoiseModel(0.0, 0.1, seed=3).apply(np.zeros(1000))
    assert dark.min() >= 0 and dark.max() > 0


def test_bad_simulation_inputs() -> None:
    spec = Analytic()
    cells = np.deg2rad([[20.0, 30.0, 40.0]])
    with pytest.raises(SamplesError, match=">= 0"):
        NoiseModel(-0.1)
    with pytest.raises(SamplesError, match=r"\(n, 3\)"):
        simulate_samples(spec, cells[:, :2], [0.0], [0.0])
    with pytest.raises(SamplesError, match="ph_lab"):
        simulate_samples(spec, cells, [0.0, 1.0], [0.0])
    with pytest.raises(SamplesError, match="stage_angles"):
        simulate_samples(spec, cells, [0.0], [])
    with pytest.raises(SamplesError, match="horizon"):
        simulate_samples(spec, np.deg2rad([[80.0, 80.0, 0.0]]), [0.0], [0.0])
    with pytest.raises(SamplesError, match="at least one rotation"):
        uniform_stage_angles(0)


def test_uniform_stage_angles_over_half_and_full_turns() -> None:
    np.testing.assert_allclose(np.rad2deg(uniform_stage_angles(4)), [0, 90, 180, 270])
    np.testing.assert_allclose(np.rad2deg(uniform_stage_angles(4, np.deg2rad(10), np.pi)),
                               [10, 55, 100, 145])
    assert span_periods(180.0) == 2 and span_periods(360.0) == 1
    with pytest.raises(SamplesError, match="180 or 360"):
        span_periods(90.0)


def test_pair_directions_are_above_the_specimen() -> None:
    wi, wo = pair_directions(np.deg2rad([[30.0, 20.0, 45.0]]), [0.5])
    assert wi.shape == wo.shape == (1, 3)
    assert wi[0, 2] > 0 and wo[0, 2] > 0


def _samples() -> Samples:
    return Samples(
        cells=np.deg2rad([[20.0, 30.0, 40.0], [5.0, 10.0, 15.0]]),
        ph_lab=np.array([0.1, 0.2]),
        stage_angles=uniform_stage_angles(3),
        values=np.arange(18, dtype=float).reshape(2, 3, 3),
        channels=("R", "G", "B"),
        provenance={"material": "test"},
    )


def test_samples_file_round_trip(tmp_path: Path) -> None:
    s = _samples()
    loaded = Samples.load(s.save(tmp_path / "s.npz"))
    for f in ("cells", "ph_lab", "stage_angles", "values"):
        np.testing.assert_array_equal(getattr(loaded, f), getattr(s, f))
    assert loaded.channels == s.channels
    assert loaded.provenance["material"] == "test"


def test_samples_file_errors(tmp_path: Path) -> None:
    with pytest.raises(SamplesError, match="no such samples file"):
        Samples.load(tmp_path / "none.npz")
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"garbage")
    with pytest.raises(SamplesError, match="not a readable"):
        Samples.load(bad)
    np.savez(tmp_path / "other.npz", values=np.zeros(3))
    with pytest.raises(SamplesError, match="not a gonio samples file"):
        Samples.load(tmp_path / "other.npz")
    s = _samples()
    p = s.save(tmp_path / "s.npz")
    with np.load(p) as z:
        data = {k: z[k] for k in z.files}
    data["values"] = data["values"][:, :2]
    np.savez(tmp_path / "shape.npz", **data)
    with pytest.raises(SamplesError, match=r"shape.npz: values have shape"):
        Samples.load(tmp_path / "shape.npz")
    data = {k: v for k, v in data.items() if k != "ph_lab"}
    np.savez(tmp_path / "missing.npz", **data)
    with pytest.raises(SamplesError, match="missing fields"):
        Samples.load(tmp_path / "missing.npz")
