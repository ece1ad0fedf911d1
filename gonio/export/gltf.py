"""glTF 2.0 export: the principled fit as a metallic-roughness material with extensions.

* ``pbrMetallicRoughness``: ``baseColorFactor`` = base colour (alpha 1), ``metallicFactor`` =
  metallic, ``roughnessFactor = sqrt(alpha_b)`` (glTF squares it).
* ``KHR_materials_anisotropy`` (when ``alpha_t > alpha_b``): the extension stretches the lobe
  along the rotated tangent to ``alpha_t = mix(alpha, 1, strength^2)`` with ``alpha`` the
  base roughness squared, so ``anisotropyStrength = sqrt((alpha_t - alpha_b) / (1 -
  alpha_b))`` (1 when ``alpha_t >= 1``), and ``anisotropyRotation`` = the direction in radians,
  counter-clockwise from the tangent towards the bitangent (the extension's convention, the
  same sense as gonio's), with the tangent on the specimen's x axis (the holder mark) and
  bitangent = normal x tangent (``TANGENT.w = +1``). A mesh without tangents gets them from
  its ``TEXCOORD_0`` (the glTF spec: MikkTSpace, tangent along increasing ``u``), so the
  specimen's x must run along ``u`` there.
* ``KHR_materials_specular`` (only when the material is not fully metallic and its
  dielectric layer is not glTF's default, ``0.08 specular`` = 0.04 and weight 1):
  ``specularColorFactor = 0.08 specular / 0.04`` in every channel (up to 22.5 for the fit's
  0.9; the extension allows factors above 1), ``specularFactor = specular_weight``. The
  extension defines ``dielectric_f0 = min(0.04 specularColor, 1) specularFactor`` and
  ``dielectric_f90 = specularFactor``, gonio's model the same
  (:mod:`gonio.brdf.models.principled`); its ``fresnel_mix`` weighs the diffuse base by ``1 -
  specularFactor max_value(fr)``, which gonio's model does too
  (:class:`gonio.brdf.models.principled.LayeredDiffuse`).

:func:`principled_from_gltf` reads such a material back.

The provenance (:mod:`gonio.export.metadata`) goes into ``asset.extras`` and the material's
``extras``. By default the file holds no mesh: it is a material library to reference or merge
into a scene. ``with_mesh=True`` (``gonio export --with-mesh``) adds a preview mesh so that any
viewer shows the material: a UV sphere of radius 1 (:func:`preview_sphere`; Y up, the front
facing +Z) with normals, ``TEXCOORD_0`` and tangents, the tangent along the lines of latitude
(``+X`` at the front, ``u`` increasing with it), in one scene with one node; in a ``.gltf``
the binary data is a base64 ``data:`` URI, so the file stays one self-contained ``.gltf``.

:func:`write_glb` writes the same document in the binary container of glTF 2.0 ("GLB File
Format Specification"), which viewers that open ``.glb`` files (three.js, Blender, model-viewer)
read by its header: a 12-byte header (``uint32`` magic ``glTF``, version 2, the total length),
then chunks of ``uint32`` length, ``uint32`` type and data, each starting and ending on a 4-byte
boundary: the JSON chunk (``JSON``, padded with spaces) and, with the preview mesh, the binary
buffer (``BIN\\0``, padded with zeros), which ``buffers[0]`` names by having no ``uri``; its
``byteLength`` is the data's, without the padding. Little-endian throughout.
"""

from __future__ import annotations

import base64
import json
import math
import os
import struct
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from gonio import __version__
from gonio.atomicfile import write_atomically
from gonio.brdf.models.principled import Principled

#: Rings (latitude) and segments (longitude) of the preview sphere.
SPHERE_RINGS, SPHERE_SEGMENTS = 32, 64
_FLOAT, _USHORT = 5126, 5123  # glTF componentType codes
_ARRAY_BUFFER, _ELEMENT_ARRAY_BUFFER = 34962, 34963
#: GLB: the header's magic and version, and the two chunk types (glTF 2.0, "Binary glTF Layout").
GLB_MAGIC, GLB_VERSION = b"glTF", 2
GLB_JSON, GLB_BIN = b"JSON", b"BIN\x00"


class GltfError(ValueError):
    """The parameters cannot be expressed as a glTF material."""


def gltf_material(p: Principled, name: str, extras: Mapping[str, Any]) -> tuple[
    dict[str, Any], list[str]
]:
    """The glTF material object and the extensions it uses (module docstring)."""
    if len(p.base_color) != 3:
        raise GltfError(
            f"glTF colours have three channels; these parameters have {len(p.base_color)}"
        )
    material: dict[str, Any] = {
        "name": name,
        "pbrMetallicRoughness": {
            "baseColorFactor": [*(min(1.0, max(0.0, c)) for c in p.base_color), 1.0],
            "metallicFactor": p.metallic,
            "roughnessFactor": math.sqrt(p.alpha_b),
        },
        "extras": dict(extras),
    }
    used: list[str] = []
    ext: dict[str, Any] = {}
    if p.alpha_t > p.alpha_b * 1.001:
        strength = 1.0 if p.alpha_t >= 1.0 else math.sqrt(
            (p.alpha_t - p.alpha_b) / (1.0 - p.alpha_b))
        ext["KHR_materials_anisotropy"] = {
            "anisotropyStrength": min(1.0, strength),
            "anisotropyRotation": math.radians(p.direction_deg % 180.0),
        }
    level = min(1.0, 0.08 * p.specular)
    if p.metallic < 1.0 and (abs(level - 0.04) > 1e-3 or p.specular_weight < 1.0):
        ext["KHR_materials_specular"] = {
            "specularFactor": p.specular_weight, "specularColorFactor": [level / 0.04] * 3,
        }
    if ext:
        material["extensions"] = ext
        used = sorted(ext)
    return material, used


def principled_from_gltf(material: Mapping[str, Any]) -> Principled:
    """The principled parameters of a glTF material written by :func:`gltf_material`.

    The inverse of the module docstring's mapping: ``alpha_b = roughnessFactor^2``,
    ``alpha_t = mix(alpha_b, 1, anisotropyStrength^2)``, the direction from
    ``anisotropyRotation``, ``specular = min(0.04 specularColorFactor, 1) / 0.08`` and
    ``specular_weight = specularFactor`` (``KHR_materials_specular``; 0.5 and 1 without it).

    Raises
    ------
    GltfError
        A specular colour that is not grey (gonio's model has one grey ``F0``), or values
        outside the model's ranges.
    """
    from gonio.brdf.models.principled import PrincipledError

    pbr = material.get("pbrMetallicRoughness", {})
    ext = material.get("extensions", {})
    alpha_b = float(pbr.get("roughnessFactor", 1.0)) ** 2
    aniso = ext.get("KHR_materials_anisotropy", {})
    strength = float(aniso.get("anisotropyStrength", 0.0))
    direction = math.degrees(float(aniso.get("anisotropyRotation", 0.0)))
    spec = ext.get("KHR_materials_specular", {})
    colour = [float(c) for c in spec.get("specularColorFactor", [1.0, 1.0, 1.0])]
    factor = float(spec.get("specularFactor", 1.0))
    if max(colour) - min(colour) > 1e-9:
        raise GltfError(f"specularColorFactor {colour}: gonio's principled model has one grey "
                        "F0 (equal components)")
    try:
        return Principled(tuple(float(c) for c in pbr.get("baseColorFactor", [1.0] * 4)[:3]),
                          float(pbr.get("metallicFactor", 1.0)), min(0.04 * colour[0], 1.0) / 0.08,
                          alpha_b + (1.0 - alpha_b) * strength**2, alpha_b, direction,
                          specular_weight=factor)
    except PrincipledError as exc:
        raise GltfError(f"not a gonio principled material: {exc}") from None


def preview_sphere(rings: int = SPHERE_RINGS, segments: int = SPHERE_SEGMENTS) -> dict[
    str, NDArray[Any]
]:
    """A UV sphere of radius 1: ``position``, ``normal`` (V, 3), ``tangent`` (V, 4),
    ``texcoord`` (V, 2) float32 and ``indices`` (3T,) uint16, counter-clockwise from outside.

    ``P = (sin t sin p, cos t, sin t cos p)`` for polar angle ``t`` from +Y and longitude ``p``
    from +Z; ``u = 0.5 + p / 2 pi``, ``v = t / pi``; tangent ``dP/dp`` normalised,
    ``(cos p, 0, -sin p, 1)``. The seam and the poles repeat vertices so that every vertex has
    one UV; the pole rows use one triangle per segment (no degenerate triangles).
    """
    t = np.linspace(0.0, np.pi, rings + 1)
    ph = np.linspace(-np.pi, np.pi, segments + 1)
    tt, pp = np.meshgrid(t, ph, indexing="ij")  # (rings + 1, segments + 1)
    pos = np.stack([np.sin(tt) * np.sin(pp), np.cos(tt), np.sin(tt) * np.cos(pp)], axis=-1)
    tangent = np.stack([np.cos(pp), np.zeros_like(pp), -np.sin(pp), np.ones_like(pp)], axis=-1)
    uv = np.stack([0.5 + pp / (2 * np.pi), tt / np.pi], axis=-1)
    idx: list[tuple[int, int, int]] = []
    w = segments + 1
    for i in range(rings):
        for j in range(segments):
            a, b, c, d = i * w + j, i * w + j + 1, (i + 1) * w + j, (i + 1) * w + j + 1
            if i > 0:
                idx.append((a, c, b))
            if i < rings - 1:
                idx.append((b, c, d))
    pos32 = pos.reshape(-1, 3).astype(np.float32)
    # Normals of a unit sphere are the positions; normalised again in float32 so a validator
    # sees unit length.
    normal = pos32 / np.linalg.norm(pos32, axis=1, keepdims=True)
    return {
        "position": pos32, "normal": normal.astype(np.float32),
        "tangent": tangent.reshape(-1, 4).astype(np.float32),
        "texcoord": uv.reshape(-1, 2).astype(np.float32),
        "indices": np.asarray(idx, dtype=np.uint16).ravel(),
    }


def _add_preview_mesh(doc: dict[str, Any]) -> bytes:
    """Add :func:`preview_sphere` as buffer, views, accessors, mesh, node and scene; returns
    the buffer's bytes, which ``buffers[0]`` does not hold yet (no ``uri``): the caller embeds
    them (:func:`gltf_document`) or puts them in a GLB's binary chunk (:func:`glb_container`)."""
    sphere = preview_sphere()
    blob = bytearray()
    views: list[dict[str, Any]] = []
    accessors: list[dict[str, Any]] = []
    for key, kind in (("position", "VEC3"), ("normal", "VEC3"), ("tangent", "VEC4"),
                      ("texcoord", "VEC2"), ("indices", "SCALAR")):
        arr = sphere[key]
        while len(blob) % 4:
            blob.append(0)
        views.append({"buffer": 0, "byteOffset": len(blob), "byteLength": arr.nbytes,
                      "target": _ELEMENT_ARRAY_BUFFER if key == "indices" else _ARRAY_BUFFER})
        blob.extend(arr.tobytes())
        acc: dict[str, Any] = {
            "bufferView": len(views) - 1, "count": int(arr.shape[0]), "type": kind,
            "componentType": _USHORT if key == "indices" else _FLOAT,
        }
        if key == "position":  # required for POSITION
            acc.update(min=arr.min(axis=0).tolist(), max=arr.max(axis=0).tolist())
        accessors.append(acc)
    doc["buffers"] = [{"byteLength": len(blob)}]
    doc["bufferViews"] = views
    doc["accessors"] = accessors
    doc["meshes"] = [{
        "name": "preview sphere",
        "primitives": [{"attributes": {"POSITION": 0, "NORMAL": 1, "TANGENT": 2,
                                       "TEXCOORD_0": 3}, "indices": 4, "material": 0}],
        "extras": {"preview": "unit UV sphere; tangent along the latitude lines (+X at the "
                              "front, facing +Z), i.e. the specimen's x (holder mark) runs "
                              "horizontally across the front"},
    }]
    doc["nodes"] = [{"name": "preview", "mesh": 0}]
    doc["scenes"] = [{"nodes": [0]}]
    doc["scene"] = 0
    return bytes(blob)


def _document(p: Principled, name: str, provenance: Mapping[str, Any],
              with_mesh: bool) -> tuple[dict[str, Any], bytes]:
    """The glTF 2.0 document of one material (and the preview mesh) and its binary buffer
    (empty without the mesh; ``buffers[0]`` then has no ``uri`` yet)."""
    material, used = gltf_material(p, name, provenance)
    doc: dict[str, Any] = {
        "asset": {"version": "2.0", "generator": f"gonio {__version__}",
                  "extras": dict(provenance)},
        "materials": [material],
    }
    if used:
        doc["extensionsUsed"] = used
    blob = _add_preview_mesh(doc) if with_mesh else b""
    return doc, blob


def gltf_document(p: Principled, name: str, provenance: Mapping[str, Any],
                  with_mesh: bool = False) -> dict[str, Any]:
    """A whole glTF 2.0 JSON document holding one material (and the preview mesh, its buffer
    embedded as a base64 ``data:`` URI)."""
    doc, blob = _document(p, name, provenance, with_mesh)
    if with_mesh:
        doc["buffers"][0]["uri"] = ("data:application/octet-stream;base64,"
                                    + base64.b64encode(blob).decode("ascii"))
    return doc


def glb_container(doc: Mapping[str, Any], blob: bytes = b"") -> bytes:
    """``doc`` and its binary buffer ``blob`` in the GLB 2.0 container (module docstring).

    Parameters
    ----------
    doc : mapping
        The glTF JSON document; with a ``blob`` its ``buffers[0]`` must have no ``uri`` and
        ``byteLength = len(blob)``.
    blob : bytes
        The binary buffer, or empty for no binary chunk (the specification: omitted when
        empty).
    """
    if blob and (doc["buffers"][0].get("uri") is not None
                 or doc["buffers"][0]["byteLength"] != len(blob)):
        raise GltfError("a GLB's binary chunk is buffers[0]: it must have no uri and its "
                        "byteLength must be the chunk's")
    # Compact JSON: ASCII (json.dumps escapes the rest), so valid UTF-8 as the chunk must be.
    text = json.dumps(doc, separators=(",", ":")).encode("ascii")
    chunks = [(GLB_JSON, text + b" " * (-len(text) % 4))]
    if blob:
        chunks.append((GLB_BIN, blob + b"\x00" * (-len(blob) % 4)))
    body = b"".join(struct.pack("<I", len(data)) + kind + data for kind, data in chunks)
    return GLB_MAGIC + struct.pack("<II", GLB_VERSION, 12 + len(body)) + body


def _clean(provenance: Mapping[str, Any]) -> dict[str, Any]:
    """The provenance as JSON holds it (values JSON has not, such as paths, as text)."""
    clean: dict[str, Any] = json.loads(json.dumps(dict(provenance), default=str))
    return clean


def write_gltf(
    p: Principled, path: str | os.PathLike[str], name: str, provenance: Mapping[str, Any],
    with_mesh: bool = False,
) -> Path:
    """Write the ``.gltf`` JSON (atomically); returns the path."""
    doc = gltf_document(p, name, _clean(provenance), with_mesh)
    return write_atomically(path, json.dumps(doc, indent=2))


def write_glb(
    p: Principled, path: str | os.PathLike[str], name: str, provenance: Mapping[str, Any],
    with_mesh: bool = False,
) -> Path:
    """Write the same document as :func:`write_gltf` as a binary ``.glb`` (atomically);
    returns the path."""
    doc, blob = _document(p, name, _clean(provenance), with_mesh)
    return write_atomically(path, glb_container(doc, blob))
