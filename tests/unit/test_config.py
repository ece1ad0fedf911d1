"""Rig configuration: the example loads, round-trips, and every user error names file and key."""

from __future__ import annotations

import copy
import tomllib
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from gonio.config import ConfigError, dump_rig_config, load_rig_config, parse_rig_config
from gonio.hal import PairSpec

EXAMPLE = Path(__file__).resolve().parents[2] / "deploy" / "rig.example.toml"


@pytest.fixture()
def example() -> dict[str, Any]:
    with EXAMPLE.open("rb") as f:
        return tomllib.load(f)


def _error(data: dict[str, Any]) -> str:
    with pytest.raises(ConfigError) as info:
        parse_rig_config(data, "rig.toml")
    return str(info.value)


def test_example_loads_and_lists_all_pairs() -> None:
    cfg = load_rig_config(EXAMPLE)
    lights = [x.name for x in cfg.lights]
    sensors = [x.name for x in cfg.sensors]
    assert cfg.pair_list() == [PairSpec(light=li, sensor=s) for li in lights for s in sensors]
    assert cfg.stage.counts_per_degree == pytest.approx(4096 * 3.0 / 360)


def test_round_trip_through_file(tmp_path: Path) -> None:
    cfg = load_rig_config(EXAMPLE)
    again = load_rig_config(dump_rig_config(cfg, tmp_path / "copy.toml"))
    assert again == cfg


def test_pair_directions_are_unit_vectors_at_the_configured_angles(example: dict) -> None:
    example["pairs"] = [{"light": "L2", "sensor": "S1"}]
    cfg = parse_rig_config(example)
    (pd,) = cfg.pair_directions()
    assert pd.pair == PairSpec(light="L2", sensor="S1")
    for vec, (theta, phi) in ((pd.wi, (60.0, 120.0)), (pd.wo, (45.0, 180.0))):
        assert np.linalg.norm(vec) == pytest.approx(1.0)
        assert np.degrees(np.arccos(vec[2])) == pytest.approx(theta)
        assert np.degrees(np.arctan2(vec[1], vec[0])) % 360 == pytest.approx(phi)


def test_unknown_driver_names_the_key_and_choices(example: dict) -> None:
    example["stage"]["driver"] = "dynamxel"
    msg = _error(example)
    assert "rig.toml: stage.driver: 'dynamxel' is not one of 'dynamixel', 'zaber'" in msg


def test_missing_key_is_reported_with_its_path(example: dict) -> None:
    del example["sensors"][1]["channels"]
    assert "rig.toml: sensors[1].channels: required key is missing" in _error(example)


def test_wrong_type_shows_the_given_value(example: dict) -> None:
    example["lights"][0]["theta_deg"] = "thirty"
    msg = _error(example)
    assert "lights[0].theta_deg" in msg and "'thirty'" in msg


def test_a_number_written_as_text_is_refused_where_it_was_read_as_the_number(
    example: dict
) -> None:
    # theta_deg = "45" was taken as 45 without a word (pydantic's lax mode), so a file a
    # script wrote wrongly passed as a rig the lab had checked.
    quoted = copy.deepcopy(example)
    quoted["lights"][0]["theta_deg"] = "45"
    msg = _error(quoted)
    assert "lights[0].theta_deg: expected a number, got the text '45'" in msg, msg
    assert "without quotes" in msg, msg
    # An integer key, and a number inside a list of numbers, likewise.
    key, value = next((k, v) for k, v in example["stage"].items() if type(v) is int)
    quoted = copy.deepcopy(example)
    quoted["stage"][key] = str(value)
    assert f"stage.{key}: expected a number, got the text '{value}'" in _error(quoted)
    quoted = copy.deepcopy(example)
    quoted["sensors"][0]["gain_stages"] = ["0.1", "0.01"]
    msg = _error(quoted)
    assert "gain_stages" in msg and "expected a number" in msg, msg
    # Inside a table of lists ([calibration] dark = {S1 = [...]}), and true/false as text.
    quoted = copy.deepcopy(example)
    sensor = next(iter(quoted["calibration"]["dark"]))
    quoted["calibration"]["dark"][sensor] = ["120", "118", "131"]
    msg = _error(quoted)
    assert f"calibration.dark: expected a number at {sensor}[0], got the text '120'" in msg, msg
    # Unquoted numbers (int where a float goes, too) still read as before.
    fixed = copy.deepcopy(example)
    fixed["lights"][0]["theta_deg"] = 45
    assert parse_rig_config(fixed, "rig.toml").lights[0].theta_deg == 45.0


def test_an_out_of_range_time_says_its_unit(example: dict) -> None:
    # 200 typed as milliseconds loaded, and every reading waited over three minutes.
    example["stage"]["settle_s"] = 200
    msg = _error(example)
    assert "stage.settle_s: Input should be less than or equal to 60 (got 200); the value is " \
        "in seconds" in msg, msg
    example["stage"]["settle_s"] = float("nan")
    assert "stage.settle_s" in _error(example)
    example["stage"]["settle_s"] = 0.2
    assert parse_rig_config(example).stage.settle_s == 0.2


def test_misspelt_key_is_refused(example: dict) -> None:
    example["stage"]["sped_dps"] = 10
    assert "stage: unknown key 'sped_dps'" in _error(example)


def test_unknown_pair_device_lists_the_known_names(example: dict) -> None:
    example["pairs"] = [{"light": "L1", "sensor": "S1"}, {"light": "L1", "sensor": "S9"}]
    msg = _error(example)
    assert "pairs[1].sensor: no sensor named 'S9'; sensors are 'S1', 'S2'" in msg


def test_zaber_needs_microsteps(example: dict) -> None:
    example["stage"]["driver"] = "zaber"
    del example["stage"]["dynamixel"]
    assert "microsteps_per_degree" in _error(example)
    example["stage"]["microsteps_per_degree"] = 1600.0
    example["stage"]["zaber"] = {"device": 2, "axis": 1}
    cfg = parse_rig_config(example)
    assert cfg.stage.microsteps_per_stage_degree == pytest.approx(1600.0 * 3.0)
    assert cfg.stage.default_baudrate == 57600  # the example sets it explicitly


def test_subtable_of_the_other_driver_is_refused(example: dict) -> None:
    example["stage"]["zaber"] = {"device": 1, "axis": 1}
    assert "[stage.zaber] is given but stage.driver is 'dynamixel'" in _error(example)


def test_value_registers_must_match_channels(example: dict) -> None:
    example["sensors"][0]["channels"] = ["R", "G"]
    assert "3 entries for 2 channels" in _error(example)


def test_shared_modbus_address_is_refused(example: dict) -> None:
    example["lights"][1]["modbus"] = copy.deepcopy(example["lights"][0]["modbus"])
    assert "L2 and L1 share Modbus" in _error(example)


def test_duplicate_names_and_bad_calibration(example: dict) -> None:
    example["sensors"][1]["name"] = "L1"
    example["calibration"]["dark"] = {"S1": [1.0, 2.0]}
    msg = _error(example)
    assert "repeated: ['L1']" in msg
    assert "calibration.dark.S1: 2 values for the 3 channels of S1" in msg


def test_literal_in_register_map(example: dict) -> None:
    example["sensors"][0]["registers"]["exposure"]["type"] = "u64"
    msg = _error(example)
    assert "sensors[0].registers.exposure.type: 'u64' is not one of" in msg
    assert "'f32'" in msg


def test_file_errors_name_the_file(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"nope\.toml: no such rig config file"):
        load_rig_config(tmp_path / "nope.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text("[stage\n", encoding="utf-8")
    with pytest.raises(ConfigError, match=r"bad\.toml: not valid TOML"):
        load_rig_config(bad)


def test_gain_stages_give_the_sensor_ranges(example: dict) -> None:
    example["sensors"][0]["gain"] = 2.0
    example["sensors"][0]["gain_stages"] = [0.2, 0.02]
    s = parse_rig_config(example, "rig.toml").sensors[0]
    # Range k's sensitivity is its gain over the nominal one.
    assert s.ranges == pytest.approx((1.0, 0.2 / 2.0, 0.02 / 2.0))
    assert [s.range_gain(k) for k in range(3)] == [2.0, 0.2, 0.02]
    assert parse_rig_config(example, "rig.toml").sensors[1].ranges == (1.0,)  # none given


def test_bad_gain_stages_are_refused_with_what_to_do(example: dict) -> None:
    sensor = example["sensors"][0]
    sensor["gain_stages"] = [0.1, 0.5]
    assert "descending order" in _error(example)
    sensor["gain_stages"] = [1.0]  # not below gain = 1.0
    assert "starting below gain (1.0)" in _error(example)
    sensor["gain_stages"] = [0.0]
    assert "gain_stages" in _error(example) and "greater than 0" in _error(example)
    sensor["gain_stages"] = [0.1]
    del sensor["registers"]["gain"]
    assert "gain_stages need a gain register" in _error(example)


@pytest.mark.parametrize("text", [
    "a = " + "[" * 100_000 + "]" * 100_000,             # arrays: tomllib recurses
    "a = " + "{b=" * 100_000 + "1" + "}" * 100_000,      # inline tables: tomllib recurses
    "a." * 100_000 + "b = 1",                           # a dotted key: no recursion, but
    "[" + "t." * 100_000 + "u]\nx = 1",                 # quadratic time and memory
], ids=["arrays", "inline-tables", "dotted-key", "table-header"])
def test_a_deeply_nested_file_is_a_config_error_naming_the_file(
    tmp_path: Path, text: str
) -> None:
    deep = tmp_path / "deep.toml"
    deep.write_text(text, encoding="utf-8")
    with pytest.raises(ConfigError, match=r"deep\.toml: arrays or tables nested more than 64 "
                                          r"levels deep; a rig config needs"):
        load_rig_config(deep)


def test_nesting_within_the_limit_and_dots_in_strings_are_not_refused(tmp_path: Path) -> None:
    # 64 levels parse (then fail as a rig config, for their content); dots inside quoted keys,
    # values and multi-line strings are not key parts.
    ok = tmp_path / "ok.toml"
    ok.write_text("a = " + "[" * 63 + "1" + "]" * 63 + "\n"
                  + '"x.y.z" = "' + "." * 200 + '"\n'
                  + 'note = """\n' + "a." * 200 + "b = 1\n" + '"""\n', encoding="utf-8")
    with pytest.raises(ConfigError) as err:
        load_rig_config(ok)
    assert "nested more than" not in str(err.value)


def test_a_pair_listed_twice_is_refused_at_load_naming_both_entries(example: dict) -> None:
    # It loaded, and only a scan said "pair L1/S1 is listed twice in the plan" (a plan the
    # user never wrote); a daemon started on the file and refused every job.
    example["pairs"] = [{"light": "L1", "sensor": "S1"}, {"light": "L2", "sensor": "S2"},
                        {"light": "L1", "sensor": "S1"}]
    msg = _error(example)
    assert "pairs[2]: L1/S1 is already listed as pairs[0]; list each pair once" in msg


def test_a_calibration_factor_given_twice_is_refused_at_load(example: dict) -> None:
    # It loaded, and a scan failed later with no key path in the file.
    example["calibration"]["factors"] = [
        {"light": "L1", "sensor": "S1", "factor": [1e-5, 1e-5, 1e-5]},
        {"light": "L1", "sensor": "S1", "factor": [2e-5, 2e-5, 2e-5]},
    ]
    msg = _error(example)
    assert "calibration.factors[1]: L1/S1 is already listed as calibration.factors[0]" in msg
    assert "keep one factor per pair" in msg


def test_a_sensor_listed_twice_names_both_entries_and_what_to_do(example: dict) -> None:
    example["sensors"][1]["name"] = "S1"
    example["calibration"]["dark"] = {"S1": [1.0, 2.0, 3.0]}
    msg = _error(example)
    assert "repeated: ['S1'] (sensors[0], sensors[1]); give each device its own name" in msg


def test_a_daemon_config_given_as_the_rig_config_says_so() -> None:
    """A newcomer with both files of docs/install.md passed the daemon config where the rig
    config belongs (``gonio stage --rig daemon.toml``) and read one "unknown key" line per
    table of it, with "check the spelling": the file is the other kind, and one line says so."""
    daemon_example = EXAMPLE.with_name("daemon.example.toml")
    with pytest.raises(ConfigError) as exc:
        load_rig_config(daemon_example)
    text = str(exc.value)
    assert text.startswith("daemon.example.toml: a daemon config") and "not a rig config" in text
    assert "--config" in text and "rig_config" in text, text
    assert "unknown key" not in text and len(text.splitlines()) == 1, text



@pytest.mark.parametrize("key", ["speed_dps", "accel_dps2", "move_timeout_s"])
@pytest.mark.parametrize("bad", ["inf", "nan"])
def test_an_infinite_or_nan_number_is_refused_naming_the_file_and_key(
        example: dict, key: str, bad: str) -> None:
    """TOML writes inf and nan: 'speed_dps = inf' passed its '> 0' and was refused later by
    the driver without the file's name ('stage: accel_dps2 must be > 0, got inf'), and
    'move_timeout_s = inf' was taken, a move that never times out."""
    data = copy.deepcopy(example)
    data["stage"][key] = tomllib.loads(f"x = {bad}")["x"]  # the TOML literal, as written
    said = _error(data)
    assert "rig.toml" in said and f"stage.{key}" in said, said
