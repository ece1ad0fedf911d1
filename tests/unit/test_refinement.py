"""PosteriorRefiner: a running job's readings to its next stage angles, on its own (through
the engine: tests/unit/engine/test_adaptive_posterior.py)."""

from __future__ import annotations

import numpy as np

from gonio.brdf.reconstruction.posterior import REFINE_OFFSET, next_angles
from gonio.brdf.reconstruction.reconstruct import reconstruct
from gonio.calibration import Calibration, PairCalibration
from gonio.plans.models import AdaptivePlan
from gonio.plans.rounds import RoundRequest
from gonio.plans.validation import plan_pairs
from gonio.refinement import PosteriorRefiner
from gonio.rigdescription import RigDescription
from gonio.sim.memrig import MemRig
from tests.unit.engine.test_adaptive_posterior import BASIS
from tests.unit.test_finishing_basis_switch import EVEN, ODD


def _refiner_inputs(n_channels: int) -> tuple[PosteriorRefiner, list[float], np.ndarray,
                                              np.ndarray]:
    """A refiner for the default adaptive plan's pairs on the in-memory rig, with calibration
    factors, and two scans at its first four angles: readings that stay the same at every
    stage angle (an isotropic specimen, each pair off by its own factor) and readings that
    swing with cos 2 alpha (an anisotropic one); ``(n, 4, n_channels)`` raw counts each."""
    desc = RigDescription.from_rig(MemRig())
    pairs = plan_pairs(AdaptivePlan(), desc)
    cal = Calibration(pairs=tuple(PairCalibration(light=p.light, sensor=p.sensor,
                                                  factor=(0.5,) * n_channels) for p in pairs))
    refiner = PosteriorRefiner(lambda: BASIS, desc, pairs, cal)
    angles = [0.0, 45.0, 90.0, 135.0]
    rng = np.random.default_rng(0)
    n, a = len(pairs), np.deg2rad(angles)[None, :, None]
    iso = 0.6 * np.exp(rng.normal(0.0, 0.3, (n, 1, n_channels))) * np.ones((n, 4, n_channels))
    swing = 0.6 * (1 + 0.8 * np.cos(2 * (a + rng.uniform(0, 3, (n, 1, 1)))))
    return refiner, angles, iso, swing * np.ones((n, 4, n_channels))


def test_the_refiner_takes_sensors_of_any_channel_count() -> None:
    """A one-channel sensor (a photodiode) with calibration factors: the posterior rule plans
    (it must not fail into V&F's rule), within the plan's half turn, midpoints of its gaps."""
    refiner, angles, _iso, swing = _refiner_inputs(1)
    got = refiner.next_angles(RoundRequest(angles, swing, 12, 1.0, 1e-9, (0.0, 180.0)))
    assert refiner.last is not None
    assert got and set(got) <= {22.5, 67.5, 112.5, 157.5}


def test_a_new_angle_buys_more_where_the_readings_swing_with_it() -> None:
    """The rule offers more for the next stage angle of a specimen whose readings change with
    the stage angle than of one whose readings do not (one channel and three)."""
    for channels in (1, 3):
        refiner, angles, iso, swing = _refiner_inputs(channels)
        refiner.next_angles(RoundRequest(angles, iso, 12, 1.0, 1e-12, (0.0, 180.0)))
        assert refiner.last is not None
        flat = refiner.last.drops[0]
        refiner.next_angles(RoundRequest(angles, swing, 12, 1.0, 1e-12, (0.0, 180.0)))
        assert refiner.last.drops[0] > 2 * flat


def test_the_basis_is_asked_for_once_and_only_when_needed() -> None:
    calls = []

    def provider() -> object:
        calls.append(1)
        return BASIS

    desc = RigDescription.from_rig(MemRig())
    pairs = plan_pairs(AdaptivePlan(), desc)
    refiner = PosteriorRefiner(provider, desc, pairs)
    assert calls == [] and refiner.describe() == {}
    _, angles, _, swing = _refiner_inputs(3)
    refiner.next_angles(RoundRequest(angles, swing, 12, 1.0, 1e-9, (0.0, 180.0)))
    refiner.next_angles(RoundRequest(angles, swing, 12, 1.0, 1e-9, (0.0, 180.0)))
    assert calls == [1]
    said = refiner.describe()
    assert {"rho", "offset", "expected_log_rmse"} <= set(said)
    assert said["basis"] == "default" and "basis_note" not in said
    assert all(round(v, 8) == v for v in said.values() if isinstance(v, float))


def test_the_calibration_factors_scale_the_counts_before_the_rule() -> None:
    """Factors 0.5 on raw counts plan as the same counts halved without a calibration."""
    calibrated, angles, _, swing = _refiner_inputs(3)
    desc = RigDescription.from_rig(MemRig())
    plain = PosteriorRefiner(lambda: BASIS, desc, calibrated.pairs)
    got = calibrated.next_angles(RoundRequest(angles, swing, 12, 1.0, 1e-12, (0.0, 180.0)))
    halved = RoundRequest(angles, 0.5 * swing, 12, 1.0, 1e-12, (0.0, 180.0))
    assert plain.next_angles(halved) == got
    assert plain.describe() == calibrated.describe()
    whole = RoundRequest(angles, swing, 12, 1.0, 1e-12, (0.0, 180.0))
    assert plain.next_angles(whole) != got or plain.describe() != calibrated.describe()


def test_no_more_angles_are_planned_than_the_budget_allows() -> None:
    """``budget_angles`` is the most angles to add (four gaps would take four)."""
    refiner, angles, _, swing = _refiner_inputs(1)

    def ask(budget: int, step: float = 1.0) -> list[float]:
        return refiner.next_angles(RoundRequest(angles, swing, budget, step, 1e-12,
                                                (0.0, 180.0)))

    assert len(ask(2)) == 2
    assert ask(0) == []


def test_gaps_narrower_than_twice_the_minimum_step_are_not_split() -> None:
    """Gaps of 45 deg: with min_step_deg 30 no midpoint is 30 deg from its neighbours."""
    refiner, angles, _, swing = _refiner_inputs(1)

    def ask(step: float) -> list[float]:
        return refiner.next_angles(RoundRequest(angles, swing, 12, step, 1e-12, (0.0, 180.0)))

    assert ask(30.0) == []
    assert ask(20.0)


def _full_turn(lean: float) -> tuple[list[float], np.ndarray]:
    """Eight angles over the full turn of the default adaptive plan's pairs on the in-memory
    rig, readings swinging with cos 2 alpha times ``1 + lean cos alpha``, 3 channels."""
    desc = RigDescription.from_rig(MemRig())
    n = len(plan_pairs(AdaptivePlan(), desc))
    angles = [45.0 * k for k in range(8)]
    a = np.deg2rad(angles)[None, :, None]
    rng = np.random.default_rng(1)
    phase = rng.uniform(0, 3, (n, 1, 1))
    return angles, 0.6 * (1 + 0.8 * np.cos(2 * (a + phase))) * (1 + lean * np.cos(a)) \
        * np.ones((n, 8, 3))


def test_a_round_that_asks_for_the_asymmetric_basis_plans_with_it() -> None:
    """After an asymmetric verdict (the round's ``basis``), the rule plans with the basis
    finishing will use: its angles are next_angles' with that basis, the provider is called
    once, and describe() says so; rounds asking for the default basis never call it."""
    calls: list[int] = []

    def odd() -> object:
        calls.append(1)
        return ODD

    desc = RigDescription.from_rig(MemRig())
    pairs = plan_pairs(AdaptivePlan(), desc)
    refiner = PosteriorRefiner(lambda: EVEN, desc, pairs, asymmetric_provider=odd)
    angles, values = _full_turn(0.3)
    # A budget of 3 of the 8 midpoints: which 3 depends on the posterior planned with.
    plain = RoundRequest(angles, values, 3, 1.0, 1e-12, (0.0, 360.0))
    even = refiner.next_angles(plain)
    assert calls == [] and refiner.describe()["basis"] == "default"
    request = RoundRequest(angles, values, 3, 1.0, 1e-12, (0.0, 360.0), "asymmetric")
    got = refiner.next_angles(request)
    assert got != even
    refiner.next_angles(request)
    assert calls == [1]
    said = refiner.describe()
    assert said["basis"] == "asymmetric" and "basis_note" not in said
    rec = reconstruct(ODD, refiner.cells, refiner.ph_lab, np.deg2rad(angles), values,
                      channels=["c0", "c1", "c2"], local=None)
    want = next_angles(ODD, refiner.cells, refiner.ph_lab, angles, values, threshold=1e-12,
                       min_step_deg=1.0, budget_angles=3, per_gap=1, table=rec.table.values,
                       period_deg=360.0, arc_start_deg=0.0, cv_sample_error=rec.cv_sample_error,
                       mahalanobis=rec.mahalanobis, offset=REFINE_OFFSET)
    assert got == list(want.angles_deg)
    assert said["expected_log_rmse"] == round(float(want.expected_log_rmse), 8)


def test_without_the_asymmetric_basis_the_round_plans_with_the_default_and_says_why() -> None:
    """No provider, one that has none at hand (not built yet) or one that fails: the round
    plans with the default basis (the scan goes on) and describe() says why; a default basis
    that already holds odd harmonics is kept, as finishing keeps it."""
    desc = RigDescription.from_rig(MemRig())
    pairs = plan_pairs(AdaptivePlan(), desc)
    angles, values = _full_turn(0.3)
    request = RoundRequest(angles, values, 8, 1.0, 1e-12, (0.0, 360.0), "asymmetric")
    plain = PosteriorRefiner(lambda: EVEN, desc, pairs)
    want = plain.next_angles(RoundRequest(angles, values, 8, 1.0, 1e-12, (0.0, 360.0)))

    def broken() -> object:
        raise OSError("disk full")

    for provider, note in ((None, "no basis for specimens"), (lambda: None, "not at hand"),
                           (broken, "disk full")):
        refiner = PosteriorRefiner(lambda: EVEN, desc, pairs, asymmetric_provider=provider)
        assert refiner.next_angles(request) == want
        said = refiner.describe()
        assert said["basis"] == "default" and note in said["basis_note"]
    kept = PosteriorRefiner(lambda: ODD, desc, pairs, asymmetric_provider=lambda: EVEN)
    kept.next_angles(request)
    assert kept.describe()["basis"] == "default"
    assert "already holds odd harmonics" in kept.describe()["basis_note"]
