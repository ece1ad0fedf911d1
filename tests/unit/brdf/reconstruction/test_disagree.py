"""The disagreement round's parts (gonio.brdf.reconstruction.disagree): predictions of a table
at a scan's pairs and stage angles, the noise model in log units, where two fits disagree, the
angles chosen and which fit predicted new readings better."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest

from gonio.brdf.reconstruction.disagree import (
    candidate_angles,
    chi_square,
    chi_terms,
    choose_angles,
    disagreement,
    log_noise_var,
    metric_disagreement,
    metric_error,
    pair_cosines,
    pair_peaks,
    predict_readings,
)
from gonio.brdf.reconstruction.errors import ReconstructionError
from gonio.brdf.tables import geometry as geo
from gonio.brdf.tables.table import VALID_MASK, BRDFTable

#: Pairs well above the horizon: (th, td, pd) radians, and their lab ph.
CELLS = np.array([[0.3, 0.4, 1.0], [0.5, 0.2, 2.0], [0.2, 0.6, 0.5]])
PH_LAB = np.array([0.4, 2.5, 4.0])


def _table_of_ph(f: Callable[[np.ndarray], np.ndarray]) -> BRDFTable:
    """A table whose value depends on the half vector's azimuth ``ph`` only (every channel)."""
    v = np.broadcast_to(f(geo.PH_GRID)[None, :, None, None, None],
                        (3, geo.N_PH, *VALID_MASK.shape)).astype(np.float32)
    v = np.where(VALID_MASK[None, None], v, np.nan)
    return BRDFTable.trusted(v, ("R", "G", "B"), "ph only")


def lobe(ph: np.ndarray, centre: float = 0.0) -> np.ndarray:
    return 1.0 + 0.5 * np.cos(ph - centre)


def test_predictions_follow_the_stage_turning_the_specimen() -> None:
    """The stage turns the specimen by +alpha, so a pair at lab ph sees the specimen's
    ph - alpha (geometry.lab_to_specimen); a table of ph alone predicts f(ph_lab - alpha)."""
    table = _table_of_ph(lobe)
    alpha = np.deg2rad([0.0, 37.0, 145.0, 290.0])
    pred = predict_readings(table, CELLS, PH_LAB, alpha)
    assert pred.shape == (3, 4, 3)
    expected = lobe(PH_LAB[:, None] - alpha[None, :])
    for c in range(3):
        # Linear between 5 deg nodes along ph: within 0.2 % of the smooth function.
        np.testing.assert_allclose(pred[..., c], expected, rtol=2e-3)


def test_a_constant_table_predicts_its_constant() -> None:
    table = _table_of_ph(lambda ph: np.full_like(ph, 0.25))
    pred = predict_readings(table, CELLS, PH_LAB, candidate_angles(30.0))
    np.testing.assert_allclose(pred, 0.25, rtol=1e-6)


def test_the_log_noise_is_relative_plus_absolute() -> None:
    # Worked by hand: level 0.5, peak 2, 1 % and 1 %: 1e-4 + (0.01 * 2 / 0.5)^2 = 0.0017.
    assert float(log_noise_var(0.5, 2.0, 0.01, 0.01)) == pytest.approx(0.0017, rel=1e-12)
    assert float(log_noise_var(2.0, 2.0, 0.01, 0.0)) == pytest.approx(1e-4, rel=1e-12)
    assert np.isinf(log_noise_var(0.0, 2.0))


def test_peaks_are_per_pair_and_channel() -> None:
    v = np.arange(24, dtype=float).reshape(2, 4, 3)
    v[0, 1, 0] = np.nan
    peaks = pair_peaks(v)
    assert peaks.shape == (2, 1, 3)
    np.testing.assert_array_equal(peaks[:, 0, :], [[9, 10, 11], [21, 22, 23]])
    with pytest.raises(ReconstructionError, match=r"\(n, r, C\)"):
        pair_peaks(np.ones((2, 4)))


def test_disagreement_is_the_noise_scaled_squared_log_difference() -> None:
    peak = np.full((1, 1, 1), 1.0)
    b = np.array([[[1.0], [0.5]]])  # one pair, two angles, one channel
    a = b * np.exp([[[0.02], [0.0]]])
    d = disagreement(a, b, peak, relative=0.01, absolute=0.01)
    level = 0.5 * (1.0 + np.exp(0.02))
    expected_first = 0.02**2 / (1e-4 + (0.01 / level) ** 2)
    np.testing.assert_allclose(d, [expected_first, 0.0], rtol=1e-12)
    np.testing.assert_array_equal(disagreement(b, b, peak), [0.0, 0.0])
    with pytest.raises(ReconstructionError, match="shapes"):
        disagreement(a, b[:, :1], peak)


def test_a_fit_placed_elsewhere_disagrees_most_where_the_lobes_differ_most() -> None:
    """Two tables of ph alone, lobes 40 deg apart: the disagreement over the candidates peaks
    where the log difference of the two functions does, worked out from the functions."""
    a, b = _table_of_ph(lobe), _table_of_ph(lambda ph: lobe(ph, np.deg2rad(40.0)))
    cells, ph_lab = CELLS[:1], np.zeros(1)
    cand = candidate_angles(5.0)
    alpha = np.deg2rad(cand)
    d = disagreement(predict_readings(a, cells, ph_lab, alpha),
                     predict_readings(b, cells, ph_lab, alpha), np.full((1, 1, 3), 1.5),
                     absolute=0.0)
    exact = (np.log(lobe(-alpha)) - np.log(lobe(-alpha, np.deg2rad(40.0)))) ** 2
    assert cand[int(np.argmax(d))] == cand[int(np.argmax(exact))]
    np.testing.assert_allclose(d, 3 * exact / 1e-4, rtol=0.05, atol=1.0)


def test_chi_square_of_the_right_fit_follows_the_noise() -> None:
    """Readings drawn with 1 % relative noise about a fit's predictions: chi-square over the
    count near 1; a fit 3 % off is far above."""
    rng = np.random.default_rng(11)
    truth = rng.uniform(0.5, 2.0, size=(40, 50, 3))
    readings = truth * (1.0 + 0.01 * rng.standard_normal(truth.shape))
    peak = pair_peaks(truth)
    right = chi_square(truth, readings, peak, relative=0.01, absolute=0.0) / truth.size
    wrong = chi_square(truth * 1.03, readings, peak, relative=0.01, absolute=0.0) / truth.size
    assert right == pytest.approx(1.0, abs=0.05)
    assert wrong > 5.0
    assert chi_square(truth, truth, peak) == 0.0
    with pytest.raises(ReconstructionError, match="differ in shape"):
        chi_square(truth[:, :2], truth, peak)


def test_angles_are_chosen_by_disagreement_and_spaced() -> None:
    cand = candidate_angles(5.0)
    scores = np.zeros(cand.size)
    scores[cand == 40.0], scores[cand == 45.0], scores[cand == 200.0] = 9.0, 8.0, 5.0
    # 45 is within 10 deg of 40, so the second pick is 200; then the zero scores spread out.
    picked = choose_angles(scores, cand, [0.0, 90.0, 180.0, 270.0], 3)
    assert picked[:2] == [40.0, 200.0]
    assert picked[2] in (135.0, 315.0)  # 45 deg from the nearest angle read, the most left
    # Nothing read far enough away from a crowded turn: fewer angles than asked.
    assert choose_angles(scores, cand, list(np.arange(0.0, 360.0, 10.0)), 2) == []


def test_agreeing_fits_spread_the_round() -> None:
    cand = candidate_angles(5.0)
    picked = choose_angles(np.zeros(cand.size), cand, [0.0, 180.0], 2)
    assert sorted(picked) == [90.0, 270.0]


def test_bad_arguments_are_refused() -> None:
    with pytest.raises(ReconstructionError, match="step"):
        candidate_angles(0.0)
    with pytest.raises(ReconstructionError, match="scores for"):
        choose_angles(np.zeros(3), np.zeros(4), [], 1)
    with pytest.raises(ReconstructionError, match="cannot choose"):
        choose_angles(np.zeros(3), np.zeros(3), [], -1)


def test_pair_cosines_are_the_lights_elevation() -> None:
    """math.md 2: i = Rz(ph) Ry(th) d, d = (sin td cos pd, sin td sin pd, cos td), so
    i_z = cos th cos td - sin th sin td cos pd, whatever ph and the stage angle."""
    th, td, pd = CELLS.T
    expected = np.cos(th) * np.cos(td) - np.sin(th) * np.sin(td) * np.cos(pd)
    got = pair_cosines(CELLS, PH_LAB)
    assert got.shape == (3, 1, 1)
    np.testing.assert_allclose(got[:, 0, 0], expected, rtol=1e-12)


def test_metric_units_are_the_cosine_weighted_log() -> None:
    cos_i = np.array([0.5])[:, None, None]
    a = np.array([[[1.0], [3.0]]])
    b = np.array([[[2.0], [3.0]]])
    # Worked by hand: (ln 1.5 - ln 2)^2 at the first angle, 0 at the second.
    np.testing.assert_allclose(metric_disagreement(a, b, cos_i),
                               [(np.log(1.5) - np.log(2.0)) ** 2, 0.0], rtol=1e-12)
    readings = np.array([[[2.0], [np.nan]]])
    # Only the finite reading counts: RMS of one error is its size.
    assert metric_error(a, readings, cos_i) == pytest.approx(np.log(2.0) - np.log(1.5))
    assert np.isnan(metric_error(a, np.full_like(a, np.nan), cos_i))
    with pytest.raises(ReconstructionError, match="shapes"):
        metric_disagreement(a, b[:, :1], cos_i)
    with pytest.raises(ReconstructionError, match="differ in shape"):
        metric_error(a, b[:, :1], cos_i)


def test_chi_terms_are_per_reading_and_skip_missing_readings() -> None:
    peak = np.full((1, 1, 1), 1.0)
    pred = np.array([[[1.0], [0.5], [0.5]]])
    readings = np.array([[[1.0 * np.exp(0.01)], [np.nan], [0.5]]])
    terms = chi_terms(pred, readings, peak, relative=0.01, absolute=0.01)
    assert terms.shape == (1, 3, 1)
    # Worked by hand: 0.01^2 / (1e-4 + (0.01 / e^0.01)^2) at the first, nothing missing, 0.
    expected = 0.01**2 / (1e-4 + (0.01 / np.exp(0.01)) ** 2)
    np.testing.assert_allclose(terms[0, :, 0], [expected, 0.0, 0.0], rtol=1e-12)
    assert chi_square(pred, readings, peak) == pytest.approx(expected, rel=1e-12)
