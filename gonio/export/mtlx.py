"""MaterialX export: the principled fit as an Autodesk Standard Surface material.

Parameter mapping (MaterialX 1.39 ``standard_surface`` and its ``roughness_anisotropy`` node:
``alpha_x = r^2 / sqrt(1 - a)`` along the tangent, ``alpha_y = r^2 sqrt(1 - a)``, the tangent
turned by ``360 x specular_rotation`` degrees about the normal by a ``rotate3d`` node):

=====================  ======================================================================
input                  value
=====================  ======================================================================
base, base_color       1, the fitted base colour
metalness              metallic
specular               the dielectric's ``specular_weight`` (1 for a metal, where it is unused)
specular_color         white
specular_IOR           ``(1 + sqrt(L)) / (1 - sqrt(L))`` with the dielectric's level
                       ``L = 0.08 specular`` (1.5 for a metal, where it is unused): the
                       index whose normal-incidence reflectance ``((n - 1)/(n + 1))^2`` is
                       ``L``; above 3 (``L`` 0.25, past the input's soft range) for a
                       diffuse colour under a bright highlight (``L`` up to 0.9, IOR 37.9)
specular_roughness     ``(alpha_t alpha_b)^(1/4)``
specular_anisotropy    ``1 - alpha_b / alpha_t`` (MaterialX clamps it at 0.98)
specular_rotation      ``((180 - direction_deg) mod 180) / 360``: MaterialX turns the tangent
                       *clockwise* seen from the normal's tip (below); the renderer's tangent
                       must be the specimen's x axis (the reference mark on the holder)
=====================  ======================================================================

**Rotation sense.** The MaterialX specification (Standard Nodes, ``rotate3d``) gives the
amount in degrees but not its sense; the reference implementation shipped with MaterialX's
standard library (``stdlib/genglsl/mx_rotate_vector3.glsl``, and its OSL twin) computes
``v cos(a) + (v x axis) sin(a) + axis (axis . v)(1 - cos(a))``, i.e. Rodrigues' formula with
the cross product reversed ("MaterialX follows v' = v * M"): the tangent ``x`` about the normal
``z`` goes to ``(cos a, -sin a, 0)``, clockwise. gonio's direction is counter-clockwise, so it
is written negated (issue 26: written un-negated, the streak came out mirrored).
``tests/unit/export/test_mtlx_render.py`` renders the document's reading by that formula and
checks the highlight's direction.

**Specular strength.** The layer's reflectance is ``specular`` times the index's Fresnel
factor (MaterialX's ``dielectric_bsdf``: ``weight`` times ``F(ior)``), so at normal
incidence ``specular_weight 0.08 specular`` and at grazing angles ``specular_weight``, as in
gonio's model and glTF's ``KHR_materials_specular``. ``specular_color`` (a tint of the
reflection alone) stays white. Standard surface weighs the base under the specular layer
by one minus the layer's directional albedo (MaterialX's ``dielectric_bsdf`` throughput),
glTF by ``1 - F(v.h)``, and its dielectric Fresnel is the exact one of the index, glTF's
Schlick's; gonio's own rendering follows glTF
(:class:`gonio.brdf.models.principled.LayeredDiffuse`). Both reflect ``F0`` at normal
incidence and give the base what the layer leaves; they part towards grazing angles.
:func:`principled_from_inputs` reads the inputs back.

The document is validated against MaterialX's standard library before it is written; the
provenance (:mod:`gonio.export.metadata`) is the material's ``doc`` string, as JSON, and the
headline facts are also ``gonio_*`` attributes of the material (:data:`ATTRIBUTES`).
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from gonio.atomicfile import write_atomically
from gonio.brdf.models.principled import Principled

#: Material attributes written from the provenance: attribute name -> provenance key.
ATTRIBUTES: dict[str, str] = {
    "gonio_specimen": "specimen", "gonio_source": "source", "gonio_job_id": "job_id",
    "gonio_colour_space": "colour_space",
}


def rotation_from_direction(direction_deg: float) -> float:
    """``specular_rotation`` for a counter-clockwise tangent direction (module docstring)."""
    return ((180.0 - direction_deg) % 180.0) / 360.0


class MtlxError(ValueError):
    """The MaterialX document cannot be made or does not validate."""


def standard_surface_inputs(p: Principled) -> dict[str, float | tuple[float, float, float]]:
    """``standard_surface`` input values for principled parameters (module docstring)."""
    if len(p.base_color) != 3:
        raise MtlxError(
            f"a MaterialX colour has three channels; these parameters have {len(p.base_color)} "
            f"({', '.join(p.channels)})"
        )
    s = math.sqrt(min(0.08 * p.specular, 0.999))  # the fit stops at 0.9 (IOR 37.9)
    ior = (1.0 + s) / (1.0 - s) if p.metallic < 1.0 else 1.5
    r, g, b = p.base_color
    return {
        "base": 1.0, "base_color": (r, g, b), "metalness": p.metallic,
        "specular": p.specular_weight if p.metallic < 1.0 else 1.0,
        "specular_color": (1.0, 1.0, 1.0), "specular_IOR": ior,
        "specular_roughness": math.sqrt(math.sqrt(p.alpha_t * p.alpha_b)),
        "specular_anisotropy": min(0.98, max(0.0, 1.0 - p.alpha_b / p.alpha_t)),
        "specular_rotation": rotation_from_direction(p.direction_deg),
    }


def principled_from_inputs(inputs: Mapping[str, Any]) -> Principled:
    """Principled parameters from ``standard_surface`` input values written by
    :func:`standard_surface_inputs` (the inverse of the module docstring's mapping:
    ``F0 = ((IOR - 1)/(IOR + 1))^2``, ``alpha_t = r^2 / sqrt(1 - a)``, ``alpha_b = r^2
    sqrt(1 - a)``, direction ``(180 - 360 specular_rotation) mod 180``).

    Raises
    ------
    MtlxError
        Values outside the model's ranges, or a ``specular_color`` other than white (gonio's
        model has no tint).
    """
    from gonio.brdf.models.principled import PrincipledError

    weight, tint = float(inputs["specular"]), tuple(float(c) for c in inputs["specular_color"])
    if any(abs(c - 1.0) > 1e-6 for c in tint):
        raise MtlxError(f"specular_color {tint}: gonio's principled model has no specular "
                        "tint (white)")
    metallic = float(inputs["metalness"])
    ior = float(inputs["specular_IOR"])
    level = ((ior - 1.0) / (ior + 1.0)) ** 2 if metallic < 1.0 else 0.04
    r2 = float(inputs["specular_roughness"]) ** 2
    aspect = math.sqrt(1.0 - float(inputs["specular_anisotropy"]))
    direction = (180.0 - 360.0 * float(inputs["specular_rotation"])) % 180.0
    try:
        return Principled(tuple(float(c) for c in inputs["base_color"]), metallic, level / 0.08,
                          r2 / aspect, r2 * aspect, direction,
                          specular_weight=weight if metallic < 1.0 else 1.0)
    except PrincipledError as exc:
        raise MtlxError(f"not a gonio principled material: {exc}") from None


def read_standard_surface(text: str) -> dict[str, Any]:
    """The input values of the first ``standard_surface`` node of a MaterialX document (XML
    text), colours as tuples."""
    import MaterialX

    doc = MaterialX.createDocument()
    MaterialX.readFromXmlString(doc, text)
    nodes = doc.getNodes("standard_surface")
    if not nodes:
        raise MtlxError("the document holds no standard_surface node")
    node = nodes[0]
    out: dict[str, Any] = {}
    for inp in node.getInputs():
        v = inp.getValue()
        out[inp.getName()] = tuple(v.asTuple()) if hasattr(v, "asTuple") else v
    return out


def _library() -> Any:
    import MaterialX

    lib = MaterialX.createDocument()
    MaterialX.loadLibraries(
        MaterialX.getDefaultDataLibraryFolders(), MaterialX.getDefaultDataSearchPath(), lib
    )
    return lib


def _element_name(text: str) -> str:
    """A valid MaterialX element name from free text (letters, digits, underscores)."""
    import MaterialX

    name = MaterialX.createValidName(text or "material")
    return name if name[0].isalpha() else f"m_{name}"


def mtlx_document(p: Principled, name: str, provenance: Mapping[str, Any]) -> Any:
    """A validated ``MaterialX.Document`` with one ``standard_surface`` material.

    Raises
    ------
    MtlxError
        The document does not validate (the message is MaterialX's own).
    """
    import MaterialX

    doc = MaterialX.createDocument()
    doc.setDataLibrary(_library())
    base = _element_name(name)
    shader = doc.addNode("standard_surface", f"SR_{base}", "surfaceshader")
    for key, value in standard_surface_inputs(p).items():
        shader.setInputValue(key, MaterialX.Color3(*value) if isinstance(value, tuple) else value)
    material = doc.addMaterialNode(f"M_{base}", shader)
    material.setDocString(json.dumps(dict(provenance), default=str, sort_keys=True))
    for attr, key in ATTRIBUTES.items():
        if provenance.get(key) is not None:
            material.setAttribute(attr, str(provenance[key]))
    err = provenance.get("reconstruction_error")
    if isinstance(err, Mapping) and err.get("predicted_log_rmse") is not None:
        material.setAttribute("gonio_predicted_log_rmse", f"{err['predicted_log_rmse']:.6g}")
    rendered = (provenance.get("fits") or {}).get("principled", {}).get("rendered")
    if isinstance(rendered, Mapping) and rendered.get("value") is not None:
        material.setAttribute("gonio_rendered_difference",
                              f"{rendered['metric']} {rendered['value']:.4g}")
    ok, message = doc.validate()
    if not ok:
        raise MtlxError(f"the MaterialX document does not validate: {message.strip()}")
    return doc


def write_mtlx(
    p: Principled, path: str | os.PathLike[str], name: str, provenance: Mapping[str, Any]
) -> Path:
    """Write a validated ``.mtlx`` document (atomically); returns the path."""
    import MaterialX

    doc = mtlx_document(p, name, provenance)
    return write_atomically(path, MaterialX.writeToXmlString(doc))
