"""MaterialX export: the principled fit as an Autodesk Standard Surface material, and beside
it as an OpenPBR Surface material (``open_pbr_surface``, below) that can carry a metal's F82
tint.

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

**OpenPBR Surface.** The document holds a second material, ``M_<name>_openpbr``, whose
shader is MaterialX 1.39's ``open_pbr_surface`` (the OpenPBR 1.0 specification) of the
principled fit, whose ``specular_color`` is a metal's F82 tint (:func:`open_pbr_inputs`):
white unless a tinted fit is given (:func:`gonio.export.judge.fit_f82`; the export gives
none, docs/export.md says why). The first
material stays the ``standard_surface`` one, so readers of older gonio documents (and
:func:`read_standard_surface`) read what they read before. OpenPBR's roughness mapping is
``alpha_t = r^2 sqrt(2 / (1 + (1 - a)^2))``, ``alpha_b = (1 - a) alpha_t``, and it has no
rotation input: the anisotropy follows ``geometry_tangent``. gonio writes that input as
``normalize(cos(d) T + sin(d) (N x T))`` of the ``tangent`` and ``normal`` geometric nodes
in world space and a ``crossproduct`` (:func:`tangent_coefficients`): the direction ``d``
counter-clockwise seen from the normal's tip, as gonio's direction is, whatever the mesh's
bitangent sign (``N x T`` is glTF's bitangent with ``w = 1``). No
rotation sense of a library node is involved.

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


def tangent_coefficients(direction_deg: float) -> tuple[float, float]:
    """``(cos d, sin d)``: the weights of the tangent ``T`` and of ``N x T`` in the
    ``geometry_tangent`` of the ``open_pbr_surface`` (module docstring)."""
    d = math.radians(direction_deg)
    return math.cos(d), math.sin(d)


def open_pbr_inputs(p: Principled) -> dict[str, float | tuple[float, float, float]]:
    """``open_pbr_surface`` input values (the tangent apart) for principled parameters.

    ``base_color`` the base colour (``F0`` of a metal), ``base_metalness`` metallic,
    ``specular_color`` the metal's F82 tint (white without one), ``specular_weight`` 1 and
    ``specular_ior`` the index whose ``((n - 1)/(n + 1))^2`` is the dielectric's normal
    incidence ``specular_weight 0.08 specular`` (OpenPBR's dielectric reflects 1 at grazing
    angles, gonio's ``specular_weight``; 1.5 for a metal), roughness by OpenPBR's mapping
    (module docstring), capped at 1.

    Raises
    ------
    MtlxError
        Not three channels, or an F82 tint on a blend (OpenPBR's ``specular_color`` tints
        the dielectric as well).
    """
    if len(p.base_color) != 3:
        raise MtlxError(f"a MaterialX colour has three channels; these parameters have "
                        f"{len(p.base_color)} ({', '.join(p.channels)})")
    if p.f82_tint is not None and 0.0 < p.metallic < 1.0:
        raise MtlxError("an F82 tint on a blend of metal and dielectric: OpenPBR's "
                        "specular_color would tint the dielectric too")
    s = math.sqrt(min(p.dielectric_f0, 0.999))
    ior = (1.0 + s) / (1.0 - s) if p.metallic < 1.0 else 1.5
    a = min(1.0, max(0.0, 1.0 - p.alpha_b / p.alpha_t))
    rough = math.sqrt(p.alpha_t / math.sqrt(2.0 / (1.0 + (1.0 - a) ** 2)))
    tint = p.f82_tint if p.f82_tint is not None and p.metallic == 1.0 else (1.0, 1.0, 1.0)
    r, g, b = p.base_color
    return {
        "base_weight": 1.0, "base_color": (r, g, b), "base_metalness": p.metallic,
        "specular_weight": 1.0, "specular_color": (tint[0], tint[1], tint[2]),
        "specular_ior": ior, "specular_roughness": min(1.0, rough),
        "specular_roughness_anisotropy": a,
    }


def principled_from_open_pbr(inputs: Mapping[str, Any], direction_deg: float) -> Principled:
    """Principled parameters from ``open_pbr_surface`` values written by
    :func:`open_pbr_inputs` and the tangent's direction (:func:`read_open_pbr_surface`).

    Raises
    ------
    MtlxError
        Values outside the model's ranges.
    """
    from gonio.brdf.models.principled import PrincipledError

    metallic = float(inputs["base_metalness"])
    ior = float(inputs["specular_ior"])
    level = ((ior - 1.0) / (ior + 1.0)) ** 2 if metallic < 1.0 else 0.04
    r2 = float(inputs["specular_roughness"]) ** 2
    a = float(inputs["specular_roughness_anisotropy"])
    alpha_t = r2 * math.sqrt(2.0 / (1.0 + (1.0 - a) ** 2))
    tint = tuple(float(c) for c in inputs["specular_color"])
    try:
        return Principled(tuple(float(c) for c in inputs["base_color"]), metallic, level / 0.08,
                          alpha_t, (1.0 - a) * alpha_t, direction_deg,
                          specular_weight=float(inputs["specular_weight"]),
                          f82_tint=tint if metallic > 0.0 else None)
    except PrincipledError as exc:
        raise MtlxError(f"not a gonio principled material: {exc}") from None


def _upstream(element: Any, name: str) -> Any:
    """The node connected to input ``name`` of a node (or the input ``element`` itself when
    it is one), else :class:`MtlxError`."""
    inp = element if element.getCategory() == "input" else element.getInput(name)
    node = inp.getConnectedNode() if inp is not None else None
    if node is None:
        raise MtlxError("geometry_tangent is not normalize(cos(d) tangent + sin(d) normal x "
                        "tangent) as gonio writes it")
    return node


def read_open_pbr_surface(text: str) -> tuple[dict[str, Any], float]:
    """The input values of the first ``open_pbr_surface`` node of a MaterialX document and
    its anisotropy direction in degrees, counter-clockwise from the mesh's tangent seen from
    the normal's tip, from a ``geometry_tangent`` written as gonio writes it (module docstring).

    Raises
    ------
    MtlxError
        No such node, or a tangent input of another form.
    """
    import MaterialX

    doc = MaterialX.createDocument()
    MaterialX.readFromXmlString(doc, text)
    nodes = doc.getNodes("open_pbr_surface")
    if not nodes:
        raise MtlxError("the document holds no open_pbr_surface node")
    out: dict[str, Any] = {}
    weights = {"tangent": 0.0, "n_cross_t": 0.0}
    for inp in nodes[0].getInputs():
        if inp.getName() == "geometry_tangent":
            add = _upstream(_upstream(inp, "geometry_tangent"), "in")
            for term in ("in1", "in2"):
                mul = _upstream(add, term)
                vec = _upstream(mul, "in1")
                kind = vec.getCategory()
                if kind == "crossproduct" and (
                        _upstream(vec, "in1").getCategory() == "normal"
                        and _upstream(vec, "in2").getCategory() == "tangent"):
                    kind = "n_cross_t"
                if kind not in weights or mul.getInputValue("in2") is None:
                    raise MtlxError("geometry_tangent is not a sum of the tangent and normal "
                                    "x tangent as gonio writes it")
                weights[kind] = float(mul.getInputValue("in2"))
            continue
        v = inp.getValue()
        out[inp.getName()] = tuple(v.asTuple()) if hasattr(v, "asTuple") else v
    direction = math.degrees(math.atan2(weights["n_cross_t"], weights["tangent"])) % 180.0
    return out, direction


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


def _label(material: Any, provenance: Mapping[str, Any]) -> None:
    """The provenance on a material node: its doc string and the ``gonio_*`` attributes."""
    material.setDocString(json.dumps(dict(provenance), default=str, sort_keys=True))
    for attr, key in ATTRIBUTES.items():
        if provenance.get(key) is not None:
            material.setAttribute(attr, str(provenance[key]))
    err = provenance.get("reconstruction_error")
    if isinstance(err, Mapping) and err.get("predicted_log_rmse") is not None:
        material.setAttribute("gonio_predicted_log_rmse", f"{err['predicted_log_rmse']:.6g}")


def _add_open_pbr(doc: Any, p: Principled, base: str) -> Any:
    """The ``open_pbr_surface`` shader of ``p`` and its tangent nodes (module docstring)."""
    import MaterialX

    shader = doc.addNode("open_pbr_surface", f"SR_{base}_openpbr", "surfaceshader")
    for key, value in open_pbr_inputs(p).items():
        shader.setInputValue(key, MaterialX.Color3(*value) if isinstance(value, tuple) else value)
    tangent = doc.addNode("tangent", f"tangent_{base}_openpbr", "vector3")
    tangent.setInputValue("space", "world")
    normal = doc.addNode("normal", f"normal_{base}_openpbr", "vector3")
    normal.setInputValue("space", "world")
    across = doc.addNode("crossproduct", f"n_cross_t_{base}_openpbr", "vector3")
    across.setConnectedNode("in1", normal)
    across.setConnectedNode("in2", tangent)
    terms = []
    for what, vec, w in zip(("tangent", "n_cross_t"), (tangent, across),
                            tangent_coefficients(p.direction_deg), strict=True):
        mul = doc.addNode("multiply", f"{what}_weighted_{base}_openpbr", "vector3")
        mul.setConnectedNode("in1", vec)
        mul.setInputValue("in2", float(w))
        terms.append(mul)
    add = doc.addNode("add", f"tangent_sum_{base}_openpbr", "vector3")
    add.setConnectedNode("in1", terms[0])
    add.setConnectedNode("in2", terms[1])
    norm = doc.addNode("normalize", f"tangent_dir_{base}_openpbr", "vector3")
    norm.setConnectedNode("in", add)
    shader.setConnectedNode("geometry_tangent", norm)
    return shader


def mtlx_document(p: Principled, name: str, provenance: Mapping[str, Any],
                  openpbr: Principled | None = None) -> Any:
    """A validated ``MaterialX.Document``: a ``standard_surface`` material of ``p`` and an
    ``open_pbr_surface`` one of ``openpbr`` (default ``p``; module docstring).

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
    _label(material, provenance)
    opbr = openpbr if openpbr is not None else p
    opbr_material = doc.addMaterialNode(f"M_{base}_openpbr", _add_open_pbr(doc, opbr, base))
    _label(opbr_material, provenance)
    opbr_rendered = opbr.metrics.get("rendered")
    if isinstance(opbr_rendered, Mapping) and opbr_rendered.get("value") is not None:
        opbr_material.setAttribute("gonio_rendered_difference",
                                   f"{opbr_rendered['metric']} {opbr_rendered['value']:.4g}")
    rendered = (provenance.get("fits") or {}).get("principled", {}).get("rendered")
    if isinstance(rendered, Mapping) and rendered.get("value") is not None:
        material.setAttribute("gonio_rendered_difference",
                              f"{rendered['metric']} {rendered['value']:.4g}")
    ok, message = doc.validate()
    if not ok:
        raise MtlxError(f"the MaterialX document does not validate: {message.strip()}")
    return doc


def write_mtlx(
    p: Principled, path: str | os.PathLike[str], name: str, provenance: Mapping[str, Any],
    openpbr: Principled | None = None,
) -> Path:
    """Write a validated ``.mtlx`` document (atomically); returns the path. ``openpbr`` is
    the ``open_pbr_surface``'s fit (default ``p``; :func:`gonio.export.judge.fit_f82`)."""
    import MaterialX

    doc = mtlx_document(p, name, provenance, openpbr)
    return write_atomically(path, MaterialX.writeToXmlString(doc))
