"""Calibration (gonio.calibration): white-reference factors, readings arranged into samples, and
the refusal of readings that cannot come from a white diffuser."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from gonio.calibration import (
    Calibration,
    CalibrationError,
    calibrated_samples,
    check_white_reference,
    from_reference,
)
from gonio.hal import LabDirection, PairSpec
from gonio.sim.rig import DEFAULT_LIGHTS, DEFAULT_SENSORS, default_material, white_reference
from gonio.sim.specimen import Specimen
from gonio.store import ReadingRow

ANGLES = np.arange(8) * 45.0
GAIN_L = {"L1": 1.0, "L2": 0.7, "L3": 1.3}  # unequal lamps and sensors, as on a real rig
GAIN_S = {"S1": 2.0, "S2": 0.5, "S3": 1.0, "S4": 1.5}


def _readings(brdf: object, noise: float = 0.0, seed: int = 0) -> dict[tuple[str, str],
                                                                        np.ndarray]:
    """Readings E_l cos(theta_l) f g_s of the default simulated geometry, from the model."""
    rng = np.random.default_rng(seed)
    spec = Specimen(brdf)  # type: ignore[arg-type]
    out = {}
    for k, ld in enumerate(DEFAULT_LIGHTS):
        wi = np.asarray(LabDirection(*ld).vector())
        for m, sd in enumerate(DEFAULT_SENSORS):
            wo = np.asarray(LabDirection(*sd).vector())
            light, sensor = f"L{k + 1}", f"S{m + 1}"
            c = np.stack([spec.brdf_lab(wi, wo, a) for a in ANGLES]) * wi[2] * 1e4
            c = c * GAIN_L[light] * GAIN_S[sensor]
            out[(light, sensor)] = c * (1 + noise * rng.standard_normal(c.shape))
    return out


def test_a_white_diffuser_with_noise_passes_and_calibrates_to_albedo_over_pi() -> None:
    counts = _readings(white_reference(0.99), noise=0.01)
    cal = from_reference(0.99, counts)
    for (light, sensor), c in counts.items():
        f = cal.factor(light, sensor, 3) * c.mean(axis=0)
        np.testing.assert_allclose(f, 0.99 / math.pi, rtol=1e-9)


def test_a_specimen_on_the_stage_is_refused_naming_a_pair() -> None:
    counts = _readings(default_material())
    with pytest.raises(CalibrationError, match="does not read like a white diffuser") as exc:
        from_reference(0.99, counts)
    assert "as the stage turns" in str(exc.value)
    assert "sim-place white" in str(exc.value)


def test_an_isotropic_non_white_specimen_is_caught_by_separability() -> None:
    from gonio.brdf.models.analytic import GGX, Lambert, LobeSum

    glossy = LobeSum((Lambert((0.2, 0.2, 0.2)), GGX(alpha_x=0.3, alpha_y=0.3)), name="iso")
    counts = _readings(glossy)
    # Isotropic: every pair reads the same at every stage angle ...
    for c in counts.values():
        assert np.ptp(c, axis=0).max() <= 1e-9 * c.max()
    # ... but light x sensor factors cannot explain the readings.
    with pytest.raises(CalibrationError, match="light-times-sensor pattern"):
        check_white_reference(counts)


def test_independent_pairs_of_a_diffuser_pass_and_a_turning_specimen_fails() -> None:
    # Each light with one sensor: no separability check, the rotation check still works.
    white = _readings(white_reference(0.5))
    spec = _readings(default_material())
    keep = [("L1", "S1"), ("L2", "S2"), ("L3", "S4")]
    check_white_reference({k: white[k] for k in keep})
    with pytest.raises(CalibrationError, match="as the stage turns"):
        check_white_reference({k: spec[k] for k in keep})
    # Without the check (a caller that knows better), the factors are still computed.
    assert len(from_reference(0.5, {k: spec[k] for k in keep}, check=False).pairs) == 3


def _reading_rows() -> list[ReadingRow]:
    out = []
    for k, ang in enumerate((0.0, 120.0, 240.0)):
        for s in ("S1", "S2"):
            out.append(ReadingRow(k, ang + 360.0, ang + 360.01, "L1", s, (10.0 + k, 20.0, 30.0),
                                  (1.0, 1.0, 1.0), 0.01, 2, False, 1.0))
    return out


def test_white_reference_factor() -> None:
    cal = from_reference(0.8, {("L1", "S1"): np.array([[2.0, 4.0], [2.0, 4.0]])})
    assert cal.factor("L1", "S1", 2) == pytest.approx([0.4 / math.pi, 0.2 / math.pi])
    assert cal.factor("L9", "S1", 2) == pytest.approx([1.0, 1.0])
    with pytest.raises(CalibrationError, match="every channel must be positive"):
        from_reference(0.8, {("L1", "S1"): np.array([[0.0, 4.0]])})
    with pytest.raises(CalibrationError, match="has 2 channels"):
        cal.factor("L1", "S1", 3)


def test_samples_arrangement_and_incomplete_jobs() -> None:
    pairs = [PairSpec(light="L1", sensor="S1"), PairSpec(light="L1", sensor="S2")]
    z = np.zeros((2, 3))
    s = calibrated_samples(_reading_rows(), pairs, z, z, ("R", "G", "B"), Calibration())
    assert s.values.shape == (2, 3, 3)
    assert s.stage_angles_deg.tolist() == [0.0, 120.0, 240.0]  # modulo 360
    assert s.values[0, 1, 0] == pytest.approx(10.0)  # 11 - 1 at the second angle
    with pytest.raises(CalibrationError, match="no reading at stage angle 240"):
        calibrated_samples(_reading_rows()[:-1], pairs, z, z, ("R", "G", "B"), Calibration())


def test_calibrated_scan_as_core_samples() -> None:
    """A mirror pair 30 deg either side of the normal has its half vector on the normal
    (theta_h = 0) and theta_d = 30 deg; stage angles go from degrees to radians unchanged."""
    from gonio.calibration import CalibratedScan

    t = np.deg2rad(30.0)
    light = np.array([[np.sin(t), 0.0, np.cos(t)]])
    sensor = np.array([[-np.sin(t), 0.0, np.cos(t)]])
    values = np.arange(3.0).reshape(1, 3, 1)
    scan = CalibratedScan(pairs=[("L1", "S1")], light_dirs=light, sensor_dirs=sensor,
                          stage_angles_deg=np.array([0.0, 120.0, 240.0]), values=values,
                          channels=("Y",))
    s = scan.to_samples({"specimen": "x"})
    assert s.cells[0, 0] == pytest.approx(0.0, abs=1e-9)
    assert s.cells[0, 1] == pytest.approx(t)
    np.testing.assert_allclose(s.stage_angles, np.deg2rad([0.0, 120.0, 240.0]))
    np.testing.assert_array_equal(s.values, values)
    assert s.channels == ("Y",) and s.provenance == {"specimen": "x"}


def test_a_reading_in_a_lower_range_calibrates_to_the_same_brdf_within_noise() -> None:
    """One specimen and pair read at gain 1 (range 0) and at gain 0.01 (range 2, scale 0.01).

    The simulated counts are ``E cos(ti) f g t + dark + noise`` (gonio.sim.specimen), each
    reading's dark read in its own range, and the white reference calibrated in range 0. After
    ``(raw - dark) / scale`` both ranges must give the same BRDF: their difference within
    5 sigma of the noise the model gives, ``sigma(c) = sqrt(shot (signal + dark_rate t) +
    read^2)`` for the reading and for its dark, divided by the range scale.
    """
    from gonio.calibration import counts, readings_array
    from gonio.sim.specimen import NoiseModel, expected_counts, sample_counts

    noise = NoiseModel(saturation=1e12)  # no clipping: the two ranges see the same signal
    rng = np.random.default_rng(7)
    irradiance, t = 2.0e7, 0.01
    wi = np.asarray(LabDirection(30.0, 0.0).vector())
    wo = np.asarray(LabDirection(40.0, 170.0).vector())
    pair = [PairSpec(light="L1", sensor="S1")]

    def rows(specimen: Specimen, gain: float, k: int) -> list[ReadingRow]:
        out = []
        for j, a in enumerate(ANGLES):
            signal = expected_counts(specimen, [(wi, irradiance)], wo, a, gain, t)
            raw = sample_counts(signal, t, noise, rng)
            dark = sample_counts(np.zeros_like(signal), t, noise, rng)
            out.append(ReadingRow(j, a, a, "L1", "S1", tuple(raw), tuple(dark), t, 1, False,
                                  0.0, range_index=k, range_scale=gain))
        return out

    white = rows(Specimen(white_reference(0.99)), 1.0, 0)
    cal = from_reference(0.99, {("L1", "S1"): np.stack([counts(r) for r in white])})
    spec = Specimen(default_material())
    index = list(range(len(ANGLES)))
    v0 = readings_array(rows(spec, 1.0, 0), pair, index, 3, cal)[0]
    v2 = readings_array(rows(spec, 0.01, 2), pair, index, 3, cal)[0]
    factor = cal.factor("L1", "S1", 3)
    signal = np.stack([expected_counts(spec, [(wi, irradiance)], wo, a, 1.0, t) for a in ANGLES])
    dark_sigma = noise.sigma(0.0, t)
    sigma0 = factor * np.hypot(noise.sigma(signal, t), dark_sigma)
    sigma2 = factor * np.hypot(noise.sigma(0.01 * signal, t), dark_sigma) / 0.01
    assert np.all(np.abs(v0 - v2) < 5 * np.hypot(sigma0, sigma2))
    # Both are the BRDF (the white reference's own noise is a fraction of a per cent).
    truth = np.stack([spec.brdf_lab(wi, wo, a) for a in ANGLES])
    np.testing.assert_allclose(v0, truth, rtol=0.01)
    assert np.all(np.abs(v2 - truth) < 5 * sigma2 + 0.01 * truth)


# --------------------------------------------------------------------------- files, checked
def _cal(*factors: tuple[float, ...], albedo: float = 0.99) -> dict[str, object]:
    """A calibration as its JSON file holds it, one pair L1/S<k> per factor tuple."""
    return {"pairs": [{"light": "L1", "sensor": f"S{k + 1}", "factor": list(f)}
                      for k, f in enumerate(factors)],
            "reference_albedo": albedo, "source": "test"}


@pytest.mark.parametrize("factor", [(-1e-5, 1e-5), (0.0, 1e-5), (math.nan, 1e-5),
                                    (math.inf, 1e-5), ()])
def test_factors_must_be_finite_and_positive(factor: tuple[float, ...]) -> None:
    from pydantic import ValidationError

    with pytest.raises(ValidationError, match="factor"):
        Calibration.model_validate(_cal(factor))


def test_a_pair_may_not_have_two_factors() -> None:
    from pydantic import ValidationError

    data = _cal((1e-5,))
    data["pairs"] = data["pairs"] * 2  # type: ignore[operator]
    with pytest.raises(ValidationError, match="L1/S1 has two factors"):
        Calibration.model_validate(data)


def test_load_calibration_names_the_file_of_every_kind_of_damage(tmp_path: Path) -> None:
    import json

    from gonio.calibration import load_calibration

    path = tmp_path / "calibration.json"
    good = json.dumps(_cal((1e-5, 2e-5)))
    path.write_text(good)
    assert load_calibration(path).pairs[0].factor == (1e-5, 2e-5)
    for text in (good[:3], "[]", json.dumps(_cal((-1e-5,))), '{"pairs": 7}'):
        path.write_text(text)
        with pytest.raises(CalibrationError, match="run a calibration job again") as e:
            load_calibration(path)
        assert f"calibration file {path}" in str(e.value)
    path.write_bytes(b"\xff\xfe")
    with pytest.raises(CalibrationError, match=f"calibration file {path} cannot be read"):
        load_calibration(path)
    # Every factor that is not finite and positive, as a file holds it (NaN: JSON's common
    # extension, as json.dumps writes it); gonio serve refuses with this message.
    for factor in (-1e-5, 0.0, math.nan):
        path.write_text(json.dumps(_cal((factor,))))
        with pytest.raises(CalibrationError, match="finite and positive") as e:
            load_calibration(path)
        assert f"calibration file {path}" in str(e.value)


def test_a_factor_is_plausible_when_its_reference_reading_is_within_the_sensor_range() -> None:
    from gonio.calibration import MIN_REFERENCE_FRACTION, check_plausible

    top = 1000.0
    full = {"S1": np.array([top])}
    albedo = 0.9
    # k = (albedo / pi) / c for a reading c: at the full scale and at the least reading.
    at_top = albedo / math.pi / top
    at_floor = albedo / math.pi / (MIN_REFERENCE_FRACTION * top)
    for k in (at_top * 1.0001, at_floor * 0.9999, albedo / math.pi / 500.0):
        check_plausible(Calibration.model_validate(_cal((k,), albedo=albedo)), full, "here")
    for k in (at_top * 0.99, at_floor * 1.01):
        with pytest.raises(CalibrationError, match="here: the factors of pair L1/S1"):
            check_plausible(Calibration.model_validate(_cal((k,), albedo=albedo)), full, "here")
    # A sensor the rig does not describe is not judged.
    check_plausible(Calibration.model_validate(_cal((1e-30,))), {}, "here")


def test_the_full_scale_counts_the_lowest_gain_stage() -> None:
    """A white reference read at a long exposure saturates at the sensor's gain and is read
    again a stage lower (auto-ranging scales it back to the nominal range): its calibration
    implies a reading above the nominal range's full scale, and was refused as one no
    reference on the rig could have produced (``gonio scan --sim --exposure 0.2``). The top is
    the nominal range's times gain over the lowest stage's gain; the least plausible reading
    stays a fraction of the nominal range (raised with the top, a dim reference that loaded
    yesterday was refused)."""
    from gonio.calibration import (
        MIN_REFERENCE_FRACTION,
        SensorRange,
        check_plausible,
        sensor_full_scale,
    )
    from gonio.config import load_rig_config

    cfg = load_rig_config(Path(__file__).resolve().parents[2] / "deploy" / "rig.example.toml")
    s1 = next(s for s in cfg.sensors if s.name == "S1")
    assert (s1.gain, s1.gain_stages) == (1.0, [0.1, 0.01])  # the example's, read above
    nominal = s1.saturation_raw * np.array([abs(r.scale) for r in s1.registers.values])
    got = sensor_full_scale(cfg)["S1"]
    assert isinstance(got, SensorRange)
    np.testing.assert_allclose(got.nominal, nominal)
    np.testing.assert_allclose(got.highest, 100.0 * nominal)  # gain 1 over stage 0.01
    albedo = 0.9

    def cal(reading: float) -> Calibration:
        # The factor a white reference reading ``reading`` (all channels) implies.
        k = albedo / math.pi / reading
        return Calibration.model_validate({
            "reference_albedo": albedo, "pairs": [
                {"light": "L1", "sensor": "S1", "factor": [k] * len(nominal)}]})

    full = sensor_full_scale(cfg)
    top, floor = float(got.highest[0]), MIN_REFERENCE_FRACTION * float(nominal[0])
    for fine in (2.0 * float(nominal[0]), top * 0.999, floor * 1.01):
        check_plausible(cal(fine), full, "here")
    for wrong in (top * 1.01, floor * 0.99):
        with pytest.raises(CalibrationError, match="here: the factors of pair"):
            check_plausible(cal(wrong), full, "here")


def test_check_covers_names_the_missing_pairs_and_accepts_no_calibration() -> None:
    from gonio.calibration import PartialCalibration

    pairs = [PairSpec(light="L1", sensor=f"S{k}") for k in (1, 2, 3)]
    cal = Calibration.model_validate(_cal((1e-5,), (1e-5,)))
    cal.check_covers(pairs[:2])
    with pytest.raises(PartialCalibration, match=r"1 of the 3 pairs of the plan: L1/S3\."):
        cal.check_covers(pairs)
    Calibration().check_covers(pairs)  # none at all: sensor units, said so by the result


def test_save_calibration_writes_only_what_load_accepts(tmp_path: Path) -> None:
    from gonio.calibration import PairCalibration, load_calibration, save_calibration

    path = tmp_path / "calibration.json"
    bad = Calibration.model_construct(
        pairs=(PairCalibration.model_construct(light="L1", sensor="S1", factor=(-1.0,)),),
        reference_albedo=0.99, exposure_s=None, source="x")
    with pytest.raises(ValueError, match="finite and positive"):
        save_calibration(bad, path)
    good = Calibration.model_validate(_cal((1e-5,)))
    with pytest.raises(CalibrationError, match="outside what sensor S1 can read"):
        save_calibration(good, path, {"S1": np.array([1.0])})  # would have read 31500 of 1
    assert not path.exists()
    save_calibration(good, path, {"S1": np.array([1e6])})
    assert load_calibration(path) == good


def test_rig_config_factors_are_checked_too() -> None:
    from types import SimpleNamespace

    from gonio.calibration import from_config_factors

    bad = [SimpleNamespace(light="L1", sensor="S1", factor=[math.inf])]
    with pytest.raises(CalibrationError, match=r"rig config's \[calibration\] factors"):
        from_config_factors(bad)


def test_an_uncalibrated_scan_needs_acceptance_only_when_the_rigs_own_calibration_is_elsewhere(
    tmp_path: Path,
) -> None:
    from gonio.calibration import CALIBRATION_FILE, uncalibrated_refusal

    pairs = [PairSpec(light="L1", sensor="S1"), PairSpec(light="L1", sensor="S2")]
    own, here = tmp_path / "rig-own", tmp_path / "elsewhere"
    own.mkdir()
    here.mkdir()
    none = Calibration()
    # Nothing calibrated anywhere: a plain uncalibrated scan (warned by the dry run, no more).
    assert uncalibrated_refusal(none, pairs, own, here) is None
    (own / CALIBRATION_FILE).write_text("{}")
    # The rig's own folder holds a calibration this data directory does not apply.
    why = uncalibrated_refusal(none, pairs, own, here)
    assert why is not None and str(own / CALIBRATION_FILE) in why and str(here) in why
    # On the rig's own data directory that file would be the one in effect.
    assert uncalibrated_refusal(none, pairs, own, own) is None
    assert uncalibrated_refusal(none, pairs, None, here) is None
    # A calibration in effect covering only part of the plan is refused at submission instead
    # (check_covers names the pairs): not a case for acceptance.
    partial = Calibration.model_validate(_cal((1e-5, 1e-5, 1e-5)))
    assert uncalibrated_refusal(partial, pairs, own, here) is None
    with pytest.raises(CalibrationError, match="S2"):
        partial.check_covers(pairs)


def test_apply_multiplies_each_pairs_rows_by_its_factor() -> None:
    """The one place factors meet readings: a calibrated pair's rows times its per-channel
    factor, an uncalibrated pair's as they are (ones); NaN (no reading) stays NaN."""
    from gonio.calibration import PairCalibration

    a, b = PairSpec(light="L1", sensor="S1"), PairSpec(light="L2", sensor="S1")
    cal = Calibration(pairs=(PairCalibration(light="L1", sensor="S1", factor=(2.0, 0.5)),))
    values = np.array([[[1.0, 4.0], [3.0, np.nan]], [[5.0, 6.0], [7.0, 8.0]]])
    got = cal.apply(values, [a, b])
    want = np.array([[[2.0, 2.0], [6.0, np.nan]], [[5.0, 6.0], [7.0, 8.0]]])
    np.testing.assert_array_equal(got, want)
    np.testing.assert_array_equal(cal.apply(values[::-1], [b, a]), want[::-1])


def test_a_calibration_is_dated_by_its_readings_when_told() -> None:
    counts = {("L1", "S1"): np.full((4, 3), 1000.0)}
    # 86400 s after the Unix epoch is 1970-01-02 00:00:00 UTC.
    cal = from_reference(0.99, counts, created=86400.0, check=False)
    assert cal.created == "1970-01-02T00:00:00Z"
    again = from_reference(0.99, counts, created=86400.0, check=False)
    assert again == cal  # the same readings, the same calibration
