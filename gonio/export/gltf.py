"""glTF 2.0 export: the principled fit as a metallic-roughness material with extensions.

* ``pbrMetallicRoughness``: ``baseColorFactor`` = base colour (alpha 1), ``metallicFactor`` =
  metallic, ``roughnessFactor = sqrt(alpha_b)`` (glTF squares it).
* ``KHR_materials_anisotropy`` (when ``alpha_t > alpha_b``): the extension stretches the lobe
  along the rotated tangent to ``alpha_t = mix(alpha, 1, strength^2)`` with ``alpha`` the
  base roughness squared, so ``anisotropyStrength = sqrt((alpha_t - alpha_b) / (1 -
  alpha_b))`` (1 when ``alpha_t >= 1``), and ``anisotropyRotation`` = the direction in radians,
  counter-clockwise from the tangent, which must be the specimen's x axis.
* ``KHR_materials_specular`` (only when the dielectric ``F0 = 0.08 specular`` differs from
  glTF's 0.04 and the material is not fully metallic): ``specularColorFactor = F0 / 0.04``
  in every channel, ``specularFactor = 1``.

Provenance (job, specimen, fit error) goes into ``asset.extras`` and the material's ``extras``.
The file holds no mesh: it is a material library to reference or merge into a scene.
"""

from __future__ import annotations

import json
import math
import os
import uuid
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from gonio import __version__
from gonio.brdf.models.principled import Principled


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
    f0 = 0.08 * p.specular
    if p.metallic < 1.0 and abs(f0 - 0.04) > 1e-3:
        ext["KHR_materials_specular"] = {
            "specularFactor": 1.0, "specularColorFactor": [f0 / 0.04] * 3,
        }
    if ext:
        material["extensions"] = ext
        used = sorted(ext)
    return material, used


def gltf_document(p: Principled, name: str, provenance: Mapping[str, Any]) -> dict[str, Any]:
    """A whole glTF 2.0 JSON document holding one material."""
    material, used = gltf_material(p, name, provenance)
    doc: dict[str, Any] = {
        "asset": {"version": "2.0", "generator": f"gonio {__version__}",
                  "extras": dict(provenance)},
        "materials": [material],
    }
    if used:
        doc["extensionsUsed"] = used
    return doc


def write_gltf(
    p: Principled, path: str | os.PathLike[str], name: str, provenance: Mapping[str, Any]
) -> Path:
    """Write the ``.gltf`` JSON (atomically); returns the path."""
    doc = gltf_document(p, name, json.loads(json.dumps(dict(provenance), default=str)))
    out = Path(path)
    tmp = out.with_name(f"{out.name}.{uuid.uuid4().hex[:12]}.part")  # one per writer
    try:
        tmp.write_text(json.dumps(doc, indent=2))
        os.replace(tmp, out)
    finally:
        tmp.unlink(missing_ok=True)
    return out
