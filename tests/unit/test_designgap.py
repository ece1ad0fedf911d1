"""A scan's self-estimate beside its design's expected error (issue 27 item 5): when the two
differ by more than x2 the reasons come from the scan's data; the design's number travels from
``gonio design``'s fragment into the rig config."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from gonio.brdf.reconstruction.selfcheck import (
    LOG_RMSE_CAPS,
    LOG_RMSE_MODEL,
    BasisMisfit,
    estimate_parts,
    final_log_rmse,
    final_parts,
    predict_joint_log_rmse,
)
from gonio.cli import main
from gonio.config import ConfigError, DesignExpectation, load_rig_config, read_toml
from gonio.designgap import ScanFacts, compare_with_design, design_expectation
from gonio.figures import headline_error
from gonio.rigdesign import dump_fragment, load_fragment, parse_fragment

EXAMPLE = Path(__file__).resolve().parents[2] / "deploy" / "rig.example.toml"

# The README's 10-pair design as gonio design reported it (issue 27): 0.0376 on held-out
# materials at 8 rotations over half a turn.
DESIGN = DesignExpectation(expected_log_rmse=0.0376, expected_log_rmse_measured=0.0528,
                           expected_log_rmse_synthetic=0.0136, rotations=8, span_deg=180.0,
                           noise=0.01, pairs=10)


def facts(**kw: object) -> ScanFacts:
    """A calibrated scan with the design's angles, arc and pairs; ``kw`` overrides."""
    base: dict[str, object] = dict(
        predicted_log_rmse=0.058, undetermined=0.052, outside=0.026, n_angles=8,
        span_deg=180.0, n_pairs=10, calibrated=True, rel_sample_error=0.02, readings=80)
    base.update(kw)
    return ScanFacts(**base)  # type: ignore[arg-type]


def test_within_a_factor_two_either_way_nothing_is_said() -> None:
    # 0.058 / 0.0376 = 1.54 (the scan of the default material) and 0.0376 / 0.0190
    # = 1.98: both inside the factor.
    assert compare_with_design(facts(), DESIGN) is None
    assert compare_with_design(facts(predicted_log_rmse=0.0190), DESIGN) is None
    assert compare_with_design(facts(predicted_log_rmse=float("nan")), DESIGN) is None


def test_an_undetermined_glossy_specimen_is_named_with_its_ratio() -> None:
    # 0.0997 = sqrt(0.0967^2 + 0.0243^2): the posterior's part carries 94 % of the variance.
    gap = compare_with_design(facts(predicted_log_rmse=0.0997, undetermined=0.0967,
                                    outside=0.0243), DESIGN)
    assert gap is not None
    assert gap.ratio == pytest.approx(0.0997 / 0.0376)
    text = gap.message()
    assert text.startswith("predicted_log_rmse 0.0997 is 2.7 times the design's expected "
                           "0.0376 (")
    assert "10 pairs at 8 uniform stage angles over 180 deg, 1 % reading noise, calibrated" \
        in text
    assert gap.reasons == (gap.reasons[0],)  # one cause, the right one
    assert "the readings leave this specimen undetermined: 0.0967 of its 0.0997" in text


def test_a_specimen_outside_the_library_and_its_misfit_are_named() -> None:
    gap = compare_with_design(facts(predicted_log_rmse=0.12, undetermined=0.04, outside=0.113,
                                    rel_sample_error=0.08), DESIGN)
    assert gap is not None
    assert "unlike the materials the basis was learnt from: 0.113 of its 0.12" in gap.reasons[0]
    # 8 % mean misfit against 1 % noise: 8 times.
    assert gap.reasons[1].startswith("the fit misses its own readings by 8.0 % on average, "
                                     "8 times the 1 % reading noise")
    assert len(gap.reasons) == 2


def test_departures_from_the_design_come_first() -> None:
    gap = compare_with_design(
        facts(predicted_log_rmse=0.2, undetermined=float("nan"), outside=float("nan"),
              n_angles=3, span_deg=360.0, n_pairs=9, calibrated=False, readings=27,
              ranged=4, saturated=1), DESIGN)
    assert gap is not None
    assert gap.reasons == (
        "the scan is uncalibrated (sensor units), the design assumed values in 1/sr: "
        "calibrate on the white reference",
        "3 stage angles, the design assumed 8",
        "the angles covered 360 deg, the design assumed 180 deg",
        "9 pairs measured, the design has 10",
        "4 of 27 readings were taken at a lower sensor gain (bright specular peaks, "
        "auto-ranged)",
        "1 of 27 readings saturated",
    )


def test_far_below_the_design_says_the_specimen_is_easy_and_more_angles_help() -> None:
    gap = compare_with_design(facts(predicted_log_rmse=0.012, undetermined=0.011,
                                    outside=0.005, n_angles=16), DESIGN)
    assert gap is not None
    assert gap.ratio == pytest.approx(0.012 / 0.0376)
    assert gap.message().startswith("predicted_log_rmse 0.012 is 3.1 times below the "
                                    "design's expected 0.0376")
    assert gap.reasons[0] == "16 stage angles, the design assumed 8"
    assert "easier for this geometry than the design's panel" in gap.reasons[1]
    assert "their mean 0.0528, the synthetic ones' 0.0136" in gap.reasons[1]
    # A worse scan is not explained by having more angles, nor a better one by fewer.
    worse = compare_with_design(facts(predicted_log_rmse=0.2, n_angles=16), DESIGN)
    assert worse is not None and not any("stage angles," in r for r in worse.reasons)


def test_the_estimate_splits_into_its_two_parts_as_variances() -> None:
    # docs/science.md 7.1: predicted^2 = exp(a) expected^2 + exp(b) m^c cv^d.
    a, b, c, d = LOG_RMSE_MODEL
    e, m, cv = 0.03, 1e-3, 0.4
    und, out = estimate_parts(e, m, cv)
    assert und == pytest.approx(math.sqrt(math.exp(a)) * e)
    assert out == pytest.approx(math.sqrt(math.exp(b) * m ** c * cv ** d))
    assert math.hypot(und, out) == pytest.approx(predict_joint_log_rmse(e, m, cv))
    # Above the caps the witnesses count as the caps, as in the estimate itself.
    _, capped = estimate_parts(e, 10.0, 100.0)
    assert capped == pytest.approx(math.sqrt(math.exp(b) * LOG_RMSE_CAPS[0] ** c
                                             * LOG_RMSE_CAPS[1] ** d))
    assert all(math.isnan(x) for x in estimate_parts(float("nan"), m, cv))


def test_the_final_estimate_splits_into_three_parts_as_variances() -> None:
    """docs/science.md 7.1.1: final^2 = (0.61 und)^2 + (0.61 out)^2 + 0.19^2 uncovered for a
    scan whose fit holds its readings; a flagged scan's parts (factor 0.6) are scaled up
    together when the misfit floor sets the estimate."""
    e, m, cv, u = 0.03, 1e-3, 0.4, 0.2
    und, out = estimate_parts(e, m, cv)
    quiet = BasisMisfit(chi2=0.5, log_misfit=0.0, persistent_pairs=0, n_pairs=10, n_angles=8)
    parts = final_parts(e, m, cv, u, quiet)
    assert parts == pytest.approx((0.61 * und, 0.61 * out, 0.19 * math.sqrt(u)))
    assert math.hypot(*parts) == pytest.approx(
        final_log_rmse(predict_joint_log_rmse(e, m, cv), u, quiet))
    floor = BasisMisfit(chi2=900.0, log_misfit=0.5, persistent_pairs=6, n_pairs=10, n_angles=8)
    fparts = final_parts(e, m, cv, u, floor)
    assert math.hypot(*fparts) == pytest.approx(0.5)
    raw = (0.6 * und, 0.6 * out, 0.19 * math.sqrt(u))
    assert [f / r for f, r in zip(fparts, raw, strict=True)] == pytest.approx(
        [0.5 / math.hypot(*raw)] * 3)
    assert all(math.isnan(x) for x in final_parts(e, m, cv, float("nan"), quiet))


def test_a_layout_that_leaves_the_table_unseen_is_named() -> None:
    gap = compare_with_design(facts(predicted_log_rmse=0.1, undetermined=0.03, outside=0.02,
                                    unseen=0.093), DESIGN)
    assert gap is not None
    text = gap.message()
    assert "the pairs leave much of the table unseen: 0.093 of its 0.1" in text
    assert "undetermined:" not in text and "unlike the materials" not in text


def test_the_headline_carries_the_gap() -> None:
    metrics = {"predicted_log_rmse": 0.0997, "design_expected_log_rmse": 0.0376,
               "design_gap": "predicted_log_rmse 0.0997 is 2.7 times ..."}
    h = headline_error(metrics)
    assert h is not None
    assert h["text"] == "0.100 (design expected 0.0376)"
    assert h["meaning"].startswith("Warning: predicted_log_rmse 0.0997 is 2.7 times ...")
    plain = headline_error({"predicted_log_rmse": 0.058, "design_expected_log_rmse": 0.0376})
    assert plain is not None and plain["text"] == "0.058"


def test_every_export_lists_the_gap() -> None:
    from gonio.export.metadata import export_provenance

    why = "predicted_log_rmse 0.099 is 2.6 times the design's expected 0.0376 (...): ..."
    assert why in export_provenance({"specimen": "x"}, {}, {"design_gap": why}, {})["warnings"]
    assert export_provenance({"specimen": "x"}, {}, {}, {})["warnings"] == []


def test_the_design_table_travels_from_the_fragment_into_the_rig_config(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    fragment = {
        "pairs": [{"light": "L1", "sensor": "S1"}],
        "lights": [{"name": "L1", "theta_deg": 35.0, "phi_deg": 10.0}],
        "sensors": [{"name": "S1", "theta_deg": 25.0, "phi_deg": 200.0}],
        "design": DESIGN.model_dump(mode="json", exclude_none=True),
    }
    geometry = tmp_path / "geometry.toml"
    geometry.write_text(dump_fragment(fragment))
    assert load_fragment(geometry).design == DESIGN
    rig = tmp_path / "rig.toml"
    rig.write_text(EXAMPLE.read_text())
    assert main(["rig", "apply-design", str(geometry), str(rig)]) == 0
    cfg = load_rig_config(rig)
    assert cfg.design == DESIGN
    # What finishing reads: the rig config as the job's provenance records it.
    assert design_expectation(cfg.model_dump_json()) == DESIGN
    assert design_expectation(None) is None
    assert design_expectation(json.dumps({"rig": "not a rig config"})) is None
    # A design without a [design] table (hand-written) removes the old one, which described
    # another geometry, and says so.
    del fragment["design"]
    geometry.write_text(dump_fragment(fragment))
    capsys.readouterr()
    assert main(["rig", "apply-design", str(geometry), str(rig)]) == 0
    assert "removed the rig's [design] table" in capsys.readouterr().out
    assert load_rig_config(rig).design is None
    assert "design" not in read_toml(rig, noun="rig config", example="", error=ConfigError)


@pytest.mark.parametrize(("table", "words"), [
    ("expected_log_rmse = -0.1\nrotations = 8\npairs = 1", "design.expected_log_rmse"),
    ("expected_log_rmse = 0.04\nrotations = 8\npairs = 1\nspan_deg = 90.0",
     "180 or 360 degrees, got 90"),
    ("expected_log_rmse = 0.04\npairs = 1", "design.rotations"),
    ("expected_log_rmse = 0.04\nrotations = 8\npairs = 1\nnoize = 0.01",
     "design: unknown key 'noize'"),
])
def test_a_bad_design_table_is_refused_by_name(tmp_path: Path, table: str, words: str) -> None:
    text = EXAMPLE.read_text() + "\n[design]\n" + table + "\n"
    rig = tmp_path / "rig.toml"
    rig.write_text(text)
    with pytest.raises(ConfigError, match="design") as err:
        load_rig_config(rig)
    assert words in str(err.value)
    with pytest.raises(ConfigError) as err2:
        parse_fragment({"lights": [{"name": "L1", "theta_deg": 1.0, "phi_deg": 0.0}],
                        "sensors": [{"name": "S1", "theta_deg": 1.0, "phi_deg": 0.0}],
                        "design": read_toml_text(table)}, "geometry.toml")
    assert "geometry.toml: design" in str(err2.value)


@pytest.mark.parametrize(("table", "words"), [
    ('rotations = 8\npairs = 10\ncolour_instrument = "MA99"',
     "unknown instrument 'MA99'; known instruments are MA68, MA98"),
    ('rotations = 8\npairs = 10\ncolour_instrument = "MA98"\ncolour_weight = -1.0',
     "design.colour_weight"),
    ('rotations = 8\npairs = 10\ncolour_instrument = "MA98"\ncolour_weight = "high"',
     "design.colour_weight"),
    ("rotations = 8\npairs = 10\ncolour_weight = 10.0",
     "give colour_instrument with it"),
    ("rotations = 8\npairs = 10\nexpected_log_rmse_measured = 0.05",
     "needs expected_log_rmse (the design's held-out error, compared with every scan), "
     "colour_instrument"),
    ("rotations = 8\npairs = 10\nrender_mix = 1.5", "design.render_mix"),
])
def test_a_bad_colour_design_record_is_refused_by_name(tmp_path: Path, table: str,
                                                       words: str) -> None:
    rig = tmp_path / "rig.toml"
    rig.write_text(EXAMPLE.read_text() + "\n[design]\n" + table + "\n")
    with pytest.raises(ConfigError, match="design") as err:
        load_rig_config(rig)
    assert words in str(err.value)


def test_a_rendering_weighted_design_record_is_kept(tmp_path: Path) -> None:
    rig = tmp_path / "rig.toml"
    rig.write_text(EXAMPLE.read_text() + "\n[design]\nrotations = 8\npairs = 10\n"
                   "render_mix = 0.5\n")
    design = load_rig_config(rig).design
    assert design is not None and design.render_mix == 0.5


def test_a_colour_design_record_without_held_out_error_is_kept_and_not_compared(
        tmp_path: Path) -> None:
    """A colour design made without the held-out error (the API, ``--no-expected-error``):
    the rig config keeps the instrument under its known name; no scan is compared with it."""
    rig = tmp_path / "rig.toml"
    rig.write_text(EXAMPLE.read_text() + '\n[design]\nrotations = 8\npairs = 10\n'
                   'colour_instrument = "multi fx10"\ncolour_weight = 3.0\n')
    cfg = load_rig_config(rig)
    assert cfg.design is not None
    assert cfg.design.colour_instrument == "MultiFX10" and cfg.design.colour_weight == 3.0
    assert cfg.design.expected_log_rmse is None
    assert compare_with_design(facts(predicted_log_rmse=0.5), cfg.design) is None


def test_the_colour_report_covers_the_instrument_the_rig_was_designed_for(
        tmp_path: Path) -> None:
    from gonio.brdf.colour.instruments import DEFAULT_INSTRUMENTS
    from gonio.result_colour import report_instruments

    rig = tmp_path / "rig.toml"
    base = EXAMPLE.read_text() + "\n[design]\nrotations = 8\npairs = 10\n"
    rig.write_text(base + 'colour_instrument = "MultiFX10"\n')
    assert report_instruments(load_rig_config(rig).model_dump_json()) == (
        *DEFAULT_INSTRUMENTS, "MultiFX10")
    rig.write_text(base + 'colour_instrument = "ma98"\n')  # already reported
    assert report_instruments(load_rig_config(rig).model_dump_json()) == DEFAULT_INSTRUMENTS
    assert report_instruments(None) == DEFAULT_INSTRUMENTS


def test_the_config_knows_the_instruments_the_colour_core_knows() -> None:
    from gonio.brdf.colour.instruments import INSTRUMENTS
    from gonio.config import COLOUR_INSTRUMENTS

    assert tuple(INSTRUMENTS) == COLOUR_INSTRUMENTS


def read_toml_text(text: str) -> dict[str, object]:
    import tomllib

    return tomllib.loads(text)


def test_an_estimate_set_by_the_peak_floor_names_the_blow_up() -> None:
    """When the estimate is the floor at the physical peak bound, its parts describe the
    estimate before the floor; the gap names the blow-up, not a part."""
    gap = compare_with_design(facts(predicted_log_rmse=0.575, undetermined=0.05, outside=0.14,
                                    peak_excess=0.575), DESIGN)
    assert gap is not None
    assert gap.reasons[0].startswith("the reconstruction blows up where no pair looks: 0.575, "
                                     "all of its estimate, is the error the table carries "
                                     "above the physical peak bound")
    assert not any("unlike the materials" in r for r in gap.reasons)
    # A floor below the estimate changes nothing: the dominant part is named as before.
    gap = compare_with_design(facts(predicted_log_rmse=0.12, undetermined=0.04, outside=0.113,
                                    peak_excess=0.02), DESIGN)
    assert gap is not None and "unlike the materials" in gap.reasons[0]
