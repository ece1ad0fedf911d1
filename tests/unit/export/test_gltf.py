"""glTF export of principled parameters, validated by the Khronos glTF validator."""

from __future__ import annotations

import json
import math
import shutil
import subprocess
from pathlib import Path

import pytest

from gonio.brdf.models.principled import Principled
from gonio.export import gltf

GLTF_DIR = Path(__file__).resolve().parents[2] / "gltf"
BRUSHED = Principled((0.9, 0.8, 0.6), 1.0, 0.5, 0.40, 0.10, 30.0)
PLASTIC = Principled((0.6, 0.2, 0.1), 0.0, 0.8, 0.09, 0.09, 0.0)
PROV = {"job_id": 7, "specimen": "felt", "factored_fit": {"rel_mse": 0.02}}


def test_gltf_parameters() -> None:
    doc = gltf.gltf_document(BRUSHED, "b", PROV)
    (m,) = doc["materials"]
    alpha = m["pbrMetallicRoughness"]["roughnessFactor"] ** 2
    s = m["extensions"]["KHR_materials_anisotropy"]["anisotropyStrength"]
    # KHR_materials_anisotropy: alpha_t = mix(alpha, 1, strength^2), alpha_b = alpha
    assert alpha == pytest.approx(0.10)
    assert alpha + (1 - alpha) * s * s == pytest.approx(0.40)
    assert m["extensions"]["KHR_materials_anisotropy"]["anisotropyRotation"] == pytest.approx(
        math.radians(30))
    assert "KHR_materials_specular" not in m["extensions"]  # a metal: F0 is the base colour
    assert doc["asset"]["extras"]["job_id"] == 7 and doc["asset"]["version"] == "2.0"
    plastic = gltf.gltf_document(PLASTIC, "p", PROV)["materials"][0]
    assert "KHR_materials_anisotropy" not in plastic.get("extensions", {})
    spec = plastic["extensions"]["KHR_materials_specular"]
    assert 0.04 * spec["specularColorFactor"][0] == pytest.approx(0.08 * 0.8)


def _validate(path: Path) -> dict:
    node = shutil.which("node")
    if node is None:
        pytest.skip("node is not installed: the Khronos glTF validator runs on node")
    if not (GLTF_DIR / "node_modules" / "gltf-validator").is_dir():
        pytest.skip(f"the glTF validator is not installed: run 'npm install' in {GLTF_DIR}")
    proc = subprocess.run([node, str(GLTF_DIR / "validate.js"), str(path)],
                          capture_output=True, text=True, timeout=120, check=False)
    assert proc.returncode == 0, proc.stderr
    return json.loads(proc.stdout)


def test_gltf_passes_the_khronos_validator(tmp_path: Path) -> None:
    for p in (BRUSHED, PLASTIC):
        path = gltf.write_gltf(p, tmp_path / "m.gltf", "m", PROV)
        report = _validate(path)
        errors = [m for m in report["issues"]["messages"] if m["severity"] == 0]
        assert report["issues"]["numErrors"] == 0, errors
        assert not [m for m in report["issues"]["messages"]
                    if m["code"] == "UNSUPPORTED_EXTENSION"]


def test_the_validator_catches_a_bad_anisotropy(tmp_path: Path) -> None:
    """The validator checks the extension's schema: a strength above 1 is an error."""
    doc = gltf.gltf_document(BRUSHED, "b", PROV)
    doc["materials"][0]["extensions"]["KHR_materials_anisotropy"]["anisotropyStrength"] = 2.0
    path = tmp_path / "bad.gltf"
    path.write_text(json.dumps(doc))
    assert _validate(path)["issues"]["numErrors"] > 0
