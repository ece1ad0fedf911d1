"""glTF export of principled parameters, validated by the Khronos glTF validator."""

from __future__ import annotations

import base64
import json
import math
import shutil
import struct
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


def _assert_valid(report: dict) -> None:
    """The Khronos validator's report has no error and no warning (listed if it has)."""
    errors = [m for m in report["issues"]["messages"] if m["severity"] == 0]
    assert report["issues"]["numErrors"] == 0, errors
    warnings = [m for m in report["issues"]["messages"] if m["severity"] == 1]
    assert report["issues"]["numWarnings"] == 0, warnings


def test_gltf_with_mesh_passes_the_khronos_validator(tmp_path: Path) -> None:
    for p in (BRUSHED, PLASTIC):
        path = gltf.write_gltf(p, tmp_path / "m.gltf", "m", PROV, with_mesh=True)
        report = _validate(path)
        _assert_valid(report)
        assert report["info"]["drawCallCount"] == 1  # the sphere is in the scene


def _glb_chunks(data: bytes) -> tuple[dict, list[tuple[bytes, bytes]]]:
    """The header and chunks of a GLB, read by the layout of the glTF 2.0 specification
    ("Binary glTF Layout"), not by gonio's writer: a 12-byte header of three little-endian
    uint32 (magic 0x46546C67 "glTF", version, total length), then chunks of uint32
    chunkLength, uint32 chunkType and chunkLength bytes of data."""
    magic, version, length = struct.unpack_from("<III", data, 0)
    header = {"magic": magic, "version": version, "length": length}
    chunks, at = [], 12
    while at < len(data):
        size, kind = struct.unpack_from("<I4s", data, at)
        chunks.append((kind, data[at + 8:at + 8 + size]))
        assert at % 4 == 0 and size % 4 == 0, (at, size)  # chunks start and end aligned
        at += 8 + size
    assert at == len(data), "the last chunk runs past the end of the file"
    return header, chunks


@pytest.mark.parametrize("with_mesh", [False, True])
def test_glb_has_the_specifications_layout(tmp_path: Path, with_mesh: bool) -> None:
    """The .glb is the .gltf's document in the binary container: header magic, version 2 and
    the file's length; the JSON chunk first (padded with spaces), then with the mesh one BIN
    chunk (padded with zeros) holding buffer 0, which has no uri and the data's length."""
    path = gltf.write_glb(BRUSHED, tmp_path / "m.glb", "m", PROV, with_mesh=with_mesh)
    data = path.read_bytes()
    header, chunks = _glb_chunks(data)
    assert header == {"magic": 0x46546C67, "version": 2, "length": len(data)}
    assert data[:4] == b"glTF"
    assert [kind for kind, _ in chunks] == [b"JSON", b"BIN\x00"][:1 + with_mesh]
    text = chunks[0][1]
    # Padded with spaces only, fewer than four, after the JSON's closing brace.
    assert text.rstrip(b" ").endswith(b"}") and len(text) - len(text.rstrip(b" ")) < 4
    doc = json.loads(text.decode("utf-8"))
    same = json.loads(gltf.write_gltf(BRUSHED, tmp_path / "m.gltf", "m", PROV,
                                      with_mesh=with_mesh).read_text())
    assert doc["materials"] == same["materials"] and doc["asset"] == same["asset"]
    assert doc["extensionsUsed"] == ["KHR_materials_anisotropy"]
    if not with_mesh:
        assert "buffers" not in doc and "meshes" not in doc
        return
    (buffer,) = doc["buffers"]
    assert "uri" not in buffer
    binary = chunks[1][1]
    assert buffer["byteLength"] <= len(binary) < buffer["byteLength"] + 4
    assert set(binary[buffer["byteLength"]:]) <= {0}
    for acc in doc["accessors"]:
        view = doc["bufferViews"][acc["bufferView"]]
        size = {5126: 4, 5123: 2}[acc["componentType"]] * acc["count"] * {
            "SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4}[acc["type"]]
        assert size <= view["byteLength"]
        assert view["byteOffset"] + view["byteLength"] <= buffer["byteLength"]
    # The accessors read the same numbers as the .gltf's base64 buffer.
    embedded = base64.b64decode(same["buffers"][0]["uri"].split(",", 1)[1])
    assert binary[:buffer["byteLength"]] == embedded
    assert doc["bufferViews"] == same["bufferViews"] and doc["accessors"] == same["accessors"]


def test_glb_pads_by_the_specification() -> None:
    """Hand-counted: ``{"asset":{"version":"2.0"},"buffers":[{"byteLength":5}]}`` is 56 bytes
    (no padding) and a 5-byte buffer is padded to 8 with three zeros: 12 + (8 + 56) + (8 + 8) =
    92 bytes; ``{"asset":{"version":"2.0"}}`` alone is 27, padded to 28 with one space: 48."""
    doc = {"asset": {"version": "2.0"}, "buffers": [{"byteLength": 5}]}
    data = gltf.glb_container(doc, b"\x01\x02\x03\x04\x05")
    header, chunks = _glb_chunks(data)
    assert header["length"] == len(data) == 92
    assert chunks[0] == (b"JSON", b'{"asset":{"version":"2.0"},"buffers":[{"byteLength":5}]}')
    assert chunks[1] == (b"BIN\x00", b"\x01\x02\x03\x04\x05\x00\x00\x00")
    bare = gltf.glb_container({"asset": {"version": "2.0"}})
    assert bare == (b"glTF" + struct.pack("<II", 2, 48) + struct.pack("<I", 28) + b"JSON"
                    + b'{"asset":{"version":"2.0"}} ')
    with pytest.raises(gltf.GltfError, match="no uri"):
        gltf.glb_container({"buffers": [{"byteLength": 5, "uri": "x.bin"}]}, b"12345")


@pytest.mark.parametrize("with_mesh", [False, True])
def test_glb_passes_the_khronos_validator(tmp_path: Path, with_mesh: bool) -> None:
    """Read as a .glb (by its suffix, as a viewer picks the container): no error, and with
    the mesh no warning and the sphere drawn. The JSON of a .gltf named .glb (what
    ``-f gltf -o x.glb`` wrote) is an error to it."""
    for p in (BRUSHED, PLASTIC, COATED):
        path = gltf.write_glb(p, tmp_path / "m.glb", "m", PROV, with_mesh=with_mesh)
        report = _validate(path)
        _assert_valid(report)
        assert report["info"]["drawCallCount"] == (1 if with_mesh else 0)
    wrong = gltf.write_gltf(BRUSHED, tmp_path / "json.glb", "m", PROV, with_mesh=with_mesh)
    assert _validate(wrong)["issues"]["numErrors"] > 0
