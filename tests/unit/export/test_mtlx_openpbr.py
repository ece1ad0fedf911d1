"""The ``open_pbr_surface`` material of the MaterialX export (issue 26).

Read back with MaterialX's Python package and interpreted as the OpenPBR specification and
MaterialX's node definitions say, written here independently of the exporter:

* roughness (OpenPBR "Specular", MaterialX ``open_pbr_anisotropy``): ``alpha_t = r^2
  sqrt(2 / (1 + (1 - a)^2))``, ``alpha_b = (1 - a) alpha_t``;
* the anisotropy follows ``geometry_tangent`` (no rotation input in MaterialX 1.39): the
  document's node graph is evaluated node by node (``tangent`` = T, ``normal`` = N,
  ``crossproduct``, ``multiply``, ``add``, ``normalize`` by the standard library's
  definitions) on a frame with T = x and N = z; the direction is then measured
  counter-clockwise from x seen from +z;
* the metal's ``specular_color`` is the F82 tint (OpenPBR "Metal").
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from gonio.brdf.models import analytic as bm
from gonio.brdf.models.principled import F82TintFresnel, Principled
from gonio.brdf.pictures import render
from gonio.export import mtlx
from tests.unit.export.highlight import angle_between, highlight

PROV = {"job_id": 3, "specimen": "brushed Al"}
FRAME = {"tangent": np.array([1.0, 0.0, 0.0]), "normal": np.array([0.0, 0.0, 1.0])}


def evaluate(node: Any) -> Any:
    """Value of a vector3 node of the tangent graph (module docstring)."""
    cat = node.getCategory()
    if cat in FRAME:
        assert node.getInputValue("space") == "world"
        return FRAME[cat]

    def arg(name: str) -> Any:
        inp = node.getInput(name)
        up = inp.getConnectedNode()
        return evaluate(up) if up is not None else inp.getValue()

    if cat == "multiply":
        return evaluate(node.getInput("in1").getConnectedNode()) * float(arg("in2"))
    if cat == "crossproduct":
        return np.cross(arg("in1"), arg("in2"))
    if cat == "add":
        return arg("in1") + arg("in2")
    if cat == "normalize":
        v = arg("in")
        return v / np.linalg.norm(v)
    raise AssertionError(f"unexpected node {cat}")


def opbr_reading(text: str) -> tuple[float, float, float, dict[str, Any]]:
    """``(tangent azimuth deg, alpha_t, alpha_b, inputs)`` of the document's open_pbr_surface."""
    import MaterialX

    doc = MaterialX.createDocument()
    MaterialX.readFromXmlString(doc, text)
    (shader,) = doc.getNodes("open_pbr_surface")
    v = {i.getName(): i.getValue() for i in shader.getInputs() if i.getValue() is not None}
    t = evaluate(shader.getInput("geometry_tangent").getConnectedNode())
    r2, a = v["specular_roughness"] ** 2, v["specular_roughness_anisotropy"]
    alpha_t = r2 * math.sqrt(2.0 / (1.0 + (1.0 - a) ** 2))
    return math.degrees(math.atan2(t[1], t[0])) % 180.0, alpha_t, (1 - a) * alpha_t, v


def validate(text: str) -> None:
    import MaterialX

    doc = MaterialX.createDocument()
    MaterialX.readFromXmlString(doc, text)
    lib = MaterialX.createDocument()
    MaterialX.loadLibraries(MaterialX.getDefaultDataLibraryFolders(),
                            MaterialX.getDefaultDataSearchPath(), lib)
    doc.setDataLibrary(lib)
    ok, msg = doc.validate()
    assert ok, msg


@pytest.mark.parametrize("direction", [25.0, 88.0, 140.0])
def test_open_pbr_streaks_like_gonio(tmp_path: Path, direction: float) -> None:
    p = Principled((0.9, 0.85, 0.8), 1.0, 0.5, 0.24, 0.03, direction,
                   f82_tint=(0.8, 0.85, 0.9))
    text = mtlx.write_mtlx(p, tmp_path / "m.mtlx", "brushed", PROV, p).read_text()
    validate(text)
    tangent_deg, at, ab, v = opbr_reading(text)
    assert (at, ab) == pytest.approx((0.24, 0.03), rel=1e-5)  # float32 in the file
    assert v["specular_color"].asTuple() == pytest.approx((0.8, 0.85, 0.9), abs=1e-6)
    assert v["base_metalness"] == 1.0
    color = v["base_color"].asTuple()
    lobe = bm.Rotated(bm.GGX(at, ab, F82TintFresnel(tuple(color), (0.8, 0.85, 0.9)),
                             "separable"), math.radians(tangent_deg))
    flash = render.PointLight(0.0, 0.0)
    theirs = highlight(np.nan_to_num(render.render_sphere(lobe, flash, 256)))
    ours = highlight(np.nan_to_num(render.render_sphere(p.model(), flash, 256)))
    assert angle_between(ours.direction_deg, direction) < 2.0, ours
    assert angle_between(theirs.direction_deg, ours.direction_deg) < 2.0, (theirs, ours)


def test_standard_surface_stays_first_and_both_read_back(tmp_path: Path) -> None:
    schlick = Principled((0.9, 0.85, 0.8), 1.0, 0.5, 0.4, 0.1, 30.0)
    tinted = Principled((0.92, 0.86, 0.8), 1.0, 0.5, 0.38, 0.1, 31.0, f82_tint=(0.7, 0.8, 0.9))
    text = mtlx.write_mtlx(schlick, tmp_path / "a.mtlx", "al", PROV, tinted).read_text()
    old = mtlx.principled_from_inputs(mtlx.read_standard_surface(text))  # old readers
    assert old.base_color == pytest.approx(schlick.base_color, abs=1e-6)
    inputs, direction = mtlx.read_open_pbr_surface(text)
    back = mtlx.principled_from_open_pbr(inputs, direction)
    assert back.f82_tint == pytest.approx((0.7, 0.8, 0.9), abs=1e-6)
    assert back.base_color == pytest.approx(tinted.base_color, abs=1e-6)
    assert (back.alpha_t, back.alpha_b) == pytest.approx((0.38, 0.1), rel=1e-5)
    assert back.direction_deg == pytest.approx(31.0, abs=1e-3)
    import MaterialX

    doc = MaterialX.createDocument()
    MaterialX.readFromXmlString(doc, text)
    names = [m.getName() for m in doc.getMaterialNodes()]
    assert names == ["M_al_job3", "M_al_job3_openpbr"] or names == ["M_al", "M_al_openpbr"]
    assert doc.getMaterialNodes()[1].getAttribute("gonio_specimen") == "brushed Al"


def test_dielectric_open_pbr_keeps_normal_incidence() -> None:
    coated = Principled((0.45, 0.09, 0.09), 0.0, 11.0, 0.35, 0.06, 120.0, specular_weight=0.6)
    v = mtlx.open_pbr_inputs(coated)
    ior = float(v["specular_ior"])  # type: ignore[arg-type]
    assert ((ior - 1) / (ior + 1)) ** 2 == pytest.approx(0.6 * 0.88)
    assert v["specular_color"] == (1.0, 1.0, 1.0)


def test_bad_documents_and_parameters_are_refused() -> None:
    blend = Principled((0.5, 0.5, 0.5), 0.5, 0.5, 0.2, 0.2, 0.0, f82_tint=(0.8, 0.8, 0.8))
    with pytest.raises(mtlx.MtlxError, match="blend"):
        mtlx.open_pbr_inputs(blend)
    with pytest.raises(mtlx.MtlxError, match="no open_pbr_surface"):
        mtlx.read_open_pbr_surface('<?xml version="1.0"?><materialx version="1.39"/>')
    other = ('<?xml version="1.0"?><materialx version="1.39">'
             '<open_pbr_surface name="s" type="surfaceshader">'
             '<input name="geometry_tangent" type="vector3" nodename="t"/></open_pbr_surface>'
             '<tangent name="t" type="vector3"/></materialx>')
    with pytest.raises(mtlx.MtlxError, match="as gonio writes it"):
        mtlx.read_open_pbr_surface(other)
