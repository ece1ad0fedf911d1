"""glTF export of principled parameters, validated by the Khronos glTF validator."""

from __future__ import annotations

import base64
import json
import math
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from gonio.brdf.models.principled import Principled
from gonio.export import gltf

GLTF_DIR = Path(__file__).resolve().parents[2] / "gltf"
BRUSHED = Principled((0.9, 0.8, 0.6), 1.0, 0.5, 0.40, 0.10, 30.0)
PLASTIC = Principled((0.6, 0.2, 0.1), 0.0, 0.8, 0.09, 0.09, 0.0)
PROV = {"job_id": 7, "specimen": "felt", "factored_fit": {"rel_mse": 0.02}}
#: A red diffuse under a strong white highlight (a coated metal): level 0.88, weight 0.6.
COATED = Principled((0.45, 0.09, 0.09), 0.0, 11.0, 0.35, 0.06, 120.0, specular_weight=0.6)


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


def test_gltf_specular_strength_follows_khr_materials_specular() -> None:
    """The F0 and F90 that KHR_materials_specular defines for the written factors
    (``dielectric_f0 = min(0.04 specularColorFactor, 1) specularFactor``, ``dielectric_f90 =
    specularFactor``, glTF's default IOR 1.5 giving the 0.04) are the model's: at normal
    incidence ``0.6 x 0.88``, at grazing 0.6. Reading the material back gives the parameters."""
    m = gltf.gltf_document(COATED, "c", PROV)["materials"][0]
    spec = m["extensions"]["KHR_materials_specular"]
    colour, factor = np.asarray(spec["specularColorFactor"]), spec["specularFactor"]
    f0 = np.minimum(0.04 * colour, 1.0) * factor
    assert np.allclose(f0, 0.6 * 0.88) and factor == pytest.approx(0.6)
    assert np.allclose(f0, COATED.f0)
    assert m["pbrMetallicRoughness"]["metallicFactor"] == 0.0
    for p in (BRUSHED, PLASTIC, COATED):
        back = gltf.principled_from_gltf(gltf.gltf_document(p, "x", PROV)["materials"][0])
        assert back.specular_weight == pytest.approx(p.specular_weight)
        assert back.dielectric_f0 == pytest.approx(p.dielectric_f0)
        for a, b in ((back.alpha_t, p.alpha_t), (back.alpha_b, p.alpha_b),
                     (back.direction_deg, p.direction_deg), (back.metallic, p.metallic)):
            assert a == pytest.approx(b, rel=1e-9, abs=1e-9)
        assert np.allclose(back.base_color, p.base_color)
    tinted = json.loads(json.dumps(m))
    tinted["extensions"]["KHR_materials_specular"]["specularColorFactor"] = [20.0, 10.0, 5.0]
    with pytest.raises(gltf.GltfError, match="grey"):
        gltf.principled_from_gltf(tinted)


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
    for p in (BRUSHED, PLASTIC, COATED):
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


def _accessor(doc: dict, index: int) -> np.ndarray:
    """An accessor's data decoded from the document's base64 buffer (glTF 2.0 layout rules:
    tightly packed little-endian components in the view's byte range)."""
    acc = doc["accessors"][index]
    view = doc["bufferViews"][acc["bufferView"]]
    uri = doc["buffers"][view["buffer"]]["uri"]
    assert uri.startswith("data:application/octet-stream;base64,")
    blob = base64.b64decode(uri.split(",", 1)[1])
    dtype = {5126: "<f4", 5123: "<u2"}[acc["componentType"]]
    width = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4}[acc["type"]]
    start = view.get("byteOffset", 0) + acc.get("byteOffset", 0)
    data = np.frombuffer(blob[start:start + view["byteLength"]], dtype=dtype)
    return data[: acc["count"] * width].reshape(acc["count"], width).astype(float)


def test_preview_sphere_has_unit_normals_and_tangents_along_u(tmp_path: Path) -> None:
    doc = gltf.gltf_document(BRUSHED, "b", PROV, with_mesh=True)
    (prim,) = doc["meshes"][0]["primitives"]
    a = prim["attributes"]
    pos, nrm = _accessor(doc, a["POSITION"]), _accessor(doc, a["NORMAL"])
    tan, uv = _accessor(doc, a["TANGENT"]), _accessor(doc, a["TEXCOORD_0"])
    idx = _accessor(doc, prim["indices"]).astype(int).ravel()
    assert np.allclose(np.linalg.norm(pos, axis=1), 1.0, atol=1e-6)  # a unit sphere
    assert np.allclose(nrm, pos, atol=1e-6)  # normals point out
    assert np.allclose(np.linalg.norm(tan[:, :3], axis=1), 1.0, atol=1e-6)
    assert np.allclose(np.sum(tan[:, :3] * nrm, axis=1), 0.0, atol=1e-6)
    assert (tan[:, 3] == 1.0).all()
    # The front (facing +Z, the camera of a default viewer): tangent +X, u grows along it.
    front = np.argmin(np.linalg.norm(pos - [0.0, 0.0, 1.0], axis=1))
    assert np.allclose(tan[front, :3], [1.0, 0.0, 0.0], atol=1e-6)
    # Tangent = direction of increasing u on every triangle (the glTF/MikkTSpace convention a
    # viewer falls back to without tangents): the u-gradient agrees with the stored tangent.
    tri = idx.reshape(-1, 3)
    p0, p1, p2 = pos[tri[:, 0]], pos[tri[:, 1]], pos[tri[:, 2]]
    du1, du2 = uv[tri[:, 1], 0] - uv[tri[:, 0], 0], uv[tri[:, 2], 0] - uv[tri[:, 0], 0]
    dv1, dv2 = uv[tri[:, 1], 1] - uv[tri[:, 0], 1], uv[tri[:, 2], 1] - uv[tri[:, 0], 1]
    det = du1 * dv2 - du2 * dv1
    dpdu = ((p1 - p0) * dv2[:, None] - (p2 - p0) * dv1[:, None]) / det[:, None]
    t_mean = tan[tri, :3].mean(axis=1)
    cos = np.sum(dpdu * t_mean, axis=1) / (np.linalg.norm(dpdu, axis=1)
                                           * np.linalg.norm(t_mean, axis=1))
    assert (cos > 0.95).all()
    # Counter-clockwise seen from outside: the face normal points away from the centre.
    face = np.cross(p1 - p0, p2 - p0)
    assert (np.sum(face * (p0 + p1 + p2), axis=1) > 0).all()


def test_gltf_with_mesh_passes_the_khronos_validator(tmp_path: Path) -> None:
    for p in (BRUSHED, PLASTIC):
        path = gltf.write_gltf(p, tmp_path / "m.gltf", "m", PROV, with_mesh=True)
        report = _validate(path)
        errors = [m for m in report["issues"]["messages"] if m["severity"] == 0]
        assert report["issues"]["numErrors"] == 0, errors
        warnings = [m for m in report["issues"]["messages"] if m["severity"] == 1]
        assert report["issues"]["numWarnings"] == 0, warnings
        assert report["info"]["drawCallCount"] == 1  # the sphere is in the scene
