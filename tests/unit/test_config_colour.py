"""Rig config keys for colour: spectral bands and chart colour calibrations of sensors."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from gonio.brdf.colour.chart import ColourMatrix
from gonio.brdf.colour.spectral import SpectralBands
from gonio.config import dump_rig_config, load_rig_config, parse_rig_config
from gonio.result_colour import colour_source
from tests.unit.test_config import _error, example  # noqa: F401  (the fixture)

MATRIX = [[41.0, 36.0, 18.0], [21.0, 72.0, 7.0], [2.0, 12.0, 95.0]]


def test_spectral_bands_and_calibration_round_trip(example: dict[str, Any],  # noqa: F811
                                                   tmp_path: Path) -> None:
    s0, s1 = example["sensors"][0], example["sensors"][1]
    s0.update(wavelengths_nm=[450.0, 550.0, 650.0], bandwidths_nm=[20.0, 20.0, 30.0])
    s1["colour_calibration"] = {"matrix": MATRIX, "residual_median_de00": 0.8}
    cfg = parse_rig_config(example)
    back = load_rig_config(dump_rig_config(cfg, tmp_path / "rig.toml"))
    assert back.sensors[0].wavelengths_nm == [450.0, 550.0, 650.0]
    assert back.sensors[1].colour_calibration is not None
    assert back.sensors[1].colour_calibration.illuminant == "D65"
    rig_json = cfg.model_dump_json()
    assert colour_source(rig_json, [s0["name"]]) == {
        "bands": SpectralBands((450.0, 550.0, 650.0), (20.0, 20.0, 30.0)).as_dict()}
    cal = colour_source(rig_json, [s1["name"]])["calibration"]
    m = ColourMatrix.from_dict(cal)
    assert m.matrix == pytest.approx(np.array(MATRIX)) and m.channels == tuple(s1["channels"])
    mixed = colour_source(rig_json, [s0["name"], s1["name"]])
    assert "different colour descriptions" in mixed["error"]
    assert colour_source(None, [s0["name"]]) == {}
    plain = json.loads(rig_json)
    for s in plain["sensors"]:
        s.pop("wavelengths_nm", None)
        s["colour_calibration"] = None
    assert colour_source(json.dumps(plain), [s0["name"]]) == {}


@pytest.mark.parametrize(("change", "words"), [
    ({"wavelengths_nm": [450.0, 550.0]}, "wavelengths_nm has 2 entries for 3 channels"),
    ({"bandwidths_nm": [10.0, 10.0, 10.0]}, "give wavelengths_nm"),
    ({"wavelengths_nm": [450.0, 550.0, 650.0], "response_nm": [400.0, 500.0]},
     "needs both response_nm and responses"),
    ({"wavelengths_nm": [450.0, 550.0, 650.0], "response_nm": [500.0, 400.0],
      "responses": [[1, 0], [0, 1], [1, 1]]}, "response_nm must increase"),
    ({"wavelengths_nm": [450.0, 550.0, 650.0], "response_nm": [400.0, 500.0],
      "responses": [[1, 0], [0, 0], [1, 1]]}, "all zero"),
    ({"wavelengths_nm": [450.0, 550.0, -1.0]}, "wavelengths_nm"),
    ({"colour_calibration": {"matrix": [[1, 2], [3, 4], [5, 6]]}}, "3 rows of 3 numbers"),
    ({"colour_calibration": {"matrix": MATRIX, "illuminant": "D66"}}, "illuminant"),
    ({"colour_calibration": {"matrix": MATRIX, "method": "root-polynomial"}},
     "3 rows of 6 numbers"),
    ({"colour_calibration": {"matrix": MATRIX, "method": "cubic"}}, "method"),
    ({"colour_calibration": {"matrix": MATRIX}, "wavelengths_nm": [450.0, 550.0, 650.0]},
     "drop colour_calibration or wavelengths_nm"),
    # A chart whose columns were B, G, R fitted the matrix in that order: under an R, G, B
    # sensor it was taken silently, mixing red readings as blue.
    ({"channels": ["R", "G", "B"], "colour_calibration": {"matrix": MATRIX,
                                                          "channels": ["B", "G", "R"]}},
     "fitted for channels ['B', 'G', 'R'], the sensor's are ['R', 'G', 'B']; fit it again "
     "with gonio colour-chart CHART.csv --channels R,G,B"),
])
def test_bad_colour_keys_say_what_to_fix(example: dict[str, Any],  # noqa: F811
                                         change: dict[str, Any], words: str) -> None:
    example["sensors"][0].update(change)
    assert words in _error(example)


def test_a_root_polynomial_calibration_reaches_the_result(example: dict[str, Any],  # noqa: F811
                                                          tmp_path: Path) -> None:
    s1 = example["sensors"][1]
    rp = [[*row, 1.0, 2.0, 3.0] for row in MATRIX]
    s1["colour_calibration"] = {"matrix": rp, "method": "root-polynomial"}
    cfg = load_rig_config(dump_rig_config(parse_rig_config(example), tmp_path / "rig.toml"))
    cal = colour_source(cfg.model_dump_json(), [s1["name"]])["calibration"]
    m = ColourMatrix.from_dict(cal)
    assert m.method == "root-polynomial" and m.matrix == pytest.approx(np.array(rp))
    # XYZ = M (R, G, B, sqrt(RG), sqrt(GB), sqrt(RB)) (Finlayson et al. 2015), written out.
    r, g, b = 0.2, 0.5, 0.8
    terms = np.array([r, g, b, np.sqrt(r * g), np.sqrt(g * b), np.sqrt(r * b)])
    from gonio.brdf.colour.conditions import ViewingConditions

    assert m.to_xyz([r, g, b], ViewingConditions()) == pytest.approx(np.array(rp) @ terms)
