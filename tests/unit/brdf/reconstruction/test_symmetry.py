"""Tests of the twofold-symmetry test on readings at opposite stage angles (issue 25 item 2)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from gonio.brdf.models import analytic as bm
from gonio.brdf.reconstruction.samples import NoiseModel, simulate_samples, uniform_stage_angles
from gonio.brdf.reconstruction.symmetry import (
    SymmetryError,
    opposite_angles,
    twofold_test,
)
from gonio.brdf.tables import geometry as geo

FULL_TURN = uniform_stage_angles(8, span=2 * np.pi)  # 4 opposite pairs


def _cells(n: int, seed: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """``n`` random valid grid cells (th <= 60 deg) and random lab azimuths."""
    rng = np.random.default_rng(seed)
    th, td, pd = geo.grid_angles()
    ok = geo.valid_mask() & (th <= np.deg2rad(60))
    idx = rng.choice(np.flatnonzero(ok), size=n, replace=False)
    cells = np.stack([th.ravel()[idx], td.ravel()[idx], pd.ravel()[idx]], axis=1)
    return cells, rng.uniform(0, 2 * np.pi, n)


def _symmetric() -> bm.BRDFModel:
    """A diffuse base under an anisotropic GGX lobe turned by an arbitrary holder angle:
    GGX's distribution and masking depend on h and w only through squares of their
    components, so the lobe reads the same turned by half a turn."""
    lobe = bm.GGX(0.12, 0.35, bm.DielectricFresnel(1.5))
    return bm.Rotated(bm.LobeSum((bm.Lambert(0.3), lobe), weights=(0.9, 1.0)), np.deg2rad(37.0))


def _tilted() -> bm.BRDFModel:
    """The same lobe on facets leaning 15 deg one way: no twofold symmetry."""
    lobe = bm.GGX(0.12, 0.35, bm.DielectricFresnel(1.5))
    base = bm.LobeSum((bm.Lambert(0.3), lobe), weights=(0.9, 1.0))
    return bm.Rotated(bm.Tilted(base, np.deg2rad(15.0), 0.4), np.deg2rad(37.0))


def _clean(model: bm.BRDFModel, n: int = 10,
           alpha: np.ndarray = FULL_TURN) -> np.ndarray:
    cells, ph = _cells(n)
    return simulate_samples(model, cells, ph, alpha, noise=NoiseModel(0.0, 0.0))


def test_tilted_facets_break_the_half_turn_identity_and_plain_lobes_keep_it() -> None:
    # The premise of the tests below, checked on the model values directly.
    cells, ph = _cells(20)
    wi, wo = geo.half_diff_to_directions(cells[:, 0], ph, cells[:, 1], cells[:, 2])
    for model, same in ((_symmetric(), True), (_tilted(), False)):
        a = model.eval(wi, wo)
        b = model.eval(geo.rotate_z(wi, np.pi), geo.rotate_z(wo, np.pi))
        assert np.allclose(a, b, rtol=1e-9) is same


def test_symmetric_specimen_is_called_symmetric_and_tilted_one_is_not() -> None:
    noise = NoiseModel(0.01, seed=11)
    sym = twofold_test(FULL_TURN, noise.apply(_clean(_symmetric())), noise)
    assert sym.overall_symmetric
    assert sym.total_dof == 10 * 4 * 3  # every pair, opposite pair and channel used
    assert sym.opposite.shape == (4, 2)
    asym = twofold_test(FULL_TURN, noise.apply(_clean(_tilted())), noise)
    assert not asym.overall_symmetric
    assert asym.total_p_value < 1e-6
    assert (~asym.symmetric).sum() >= 5  # most pairs see it on their own
    assert np.nanmax(asym.rms_log_difference) > 0.1  # 10 % and more, far above 1 % noise


def _false_alarms(clean: np.ndarray, noise: NoiseModel, runs: int,
                  alpha: np.ndarray = FULL_TURN) -> tuple[np.ndarray, int]:
    out = []
    dof = 0
    for s in range(runs):
        nm = NoiseModel(noise.relative, noise.absolute, seed=1000 + s)
        t = twofold_test(alpha, nm.apply(clean), nm)
        out.append(t.total_statistic)
        dof = t.total_dof
    return np.asarray(out), dof


@pytest.mark.parametrize("noise", [NoiseModel(0.01), NoiseModel(0.01, 0.002)])
def test_statistic_follows_the_chi_square_distribution_on_symmetric_specimens(
        noise: NoiseModel) -> None:
    # 800 noisy scans of a symmetric specimen: the overall statistic is compared with scipy's
    # chi-square distribution (Kolmogorov-Smirnov) and the false-alarm rate at 5 % with the
    # binomial bounds of 800 draws at p = 0.05 (mean 40, sd 6.2).
    clean = _clean(_symmetric(), n=6)
    t, dof = _false_alarms(clean, noise, 800)
    assert stats.kstest(t, stats.chi2(dof).cdf).pvalue > 1e-3
    alarms = int(np.sum(stats.chi2.sf(t, dof) < 0.05))
    lo, hi = stats.binom(800, 0.05).ppf([0.0005, 0.9995])
    assert lo <= alarms <= hi


def test_per_pair_verdicts_have_the_stated_false_alarm_rate() -> None:
    clean = _clean(_symmetric(), n=10)
    flagged = 0
    runs = 300
    for s in range(runs):
        nm = NoiseModel(0.01, seed=5000 + s)
        flagged += int((~twofold_test(FULL_TURN, nm.apply(clean), nm,
                                      false_alarm=0.05).symmetric).sum())
    lo, hi = stats.binom(runs * 10, 0.05).ppf([0.0005, 0.9995])
    assert lo <= flagged <= hi


def test_opposite_angles_pair_each_angle_once_within_the_tolerance() -> None:
    a = np.deg2rad([0.0, 180.2, 90.0, 270.0, 45.0, 226.0, 0.0])
    pairs = opposite_angles(a)
    found = {tuple(sorted(p)) for p in pairs.tolist()}
    assert found == {(0, 1), (2, 3)}  # 45 / 226 are 1 deg off; the second 0 has no partner
    assert len(opposite_angles(a, tolerance=np.deg2rad(1.5))) == 3
    # half a turn of uniform angles never holds an opposite pair
    assert opposite_angles(uniform_stage_angles(8, span=np.pi)).shape == (0, 2)


def test_readings_without_opposite_angles_are_refused_with_advice() -> None:
    half = uniform_stage_angles(8, span=np.pi)
    vals = _clean(_symmetric(), alpha=half)
    with pytest.raises(SymmetryError, match="full turn"):
        twofold_test(half, vals, NoiseModel(0.01))


def test_bad_input_is_refused_with_a_clear_message() -> None:
    vals = _clean(_symmetric(), n=3)
    with pytest.raises(SymmetryError, match="expected"):
        twofold_test(FULL_TURN[:5], vals, NoiseModel(0.01))
    with pytest.raises(SymmetryError, match="noise model is zero"):
        twofold_test(FULL_TURN, vals, NoiseModel(0.0, 0.0))
    with pytest.raises(SymmetryError, match="false_alarm"):
        twofold_test(FULL_TURN, vals, NoiseModel(0.01), false_alarm=1.0)
    with pytest.raises(SymmetryError, match="noise floor"):
        twofold_test(FULL_TURN, np.zeros_like(vals), NoiseModel(0.01))


def test_readings_buried_in_absolute_noise_are_left_out() -> None:
    vals = _clean(_symmetric(), n=4)
    vals[0] = 1e-6  # far below the absolute noise: its log says nothing
    t = twofold_test(FULL_TURN, vals, NoiseModel(0.01, 1e-3))
    assert t.dof[0] == 0 and t.p_value[0] == 1.0 and np.isnan(t.rms_log_difference[0])
    assert (t.dof[1:] == 12).all()
