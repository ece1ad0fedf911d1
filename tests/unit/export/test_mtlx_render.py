"""The exported MaterialX document rendered as MaterialX reads it (issue 26).

MaterialX's GLSL renderer needs a GPU context; here the document is read back with MaterialX's
Python package and its ``standard_surface`` inputs are turned into a lobe the way MaterialX's
reference implementation defines them, written independently of gonio's exporter:

* the tangent: ``rotate3d`` of the geometric tangent (specimen x) about the normal by
  ``360 x specular_rotation`` degrees, with MaterialX's ``mx_rotate_vector3``
  (``test_mtlx.mx_rotate``; clockwise seen from the normal's tip);
* the roughnesses: ``mx_roughness_anisotropy`` (pbrlib): ``alpha_x = min(r^2 / aspect, 1)``
  along that tangent, ``alpha_y = r^2 aspect``, ``aspect = sqrt(1 - min(a, 0.98))``;
* a metal's Fresnel at normal incidence: ``base x base_color``.

That GGX lobe is rendered on gonio's sphere with a light at the camera, and the highlight's
direction and widths are compared with gonio's rendering of the principled fit itself.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from gonio.brdf.models import analytic as bm
from gonio.brdf.models.principled import Principled
from gonio.brdf.pictures import render
from gonio.export import mtlx
from tests.unit.export.highlight import angle_between, highlight
from tests.unit.export.test_mtlx import mx_rotate

SIZE = 256
ANGLE_TOL_DEG, WIDTH_TOL = 2.0, 0.05


def materialx_reading(path: Path) -> tuple[float, float, float, tuple[float, float, float]]:
    """``(tangent azimuth deg, alpha_x, alpha_y, F0)`` of a document's ``standard_surface``,
    as MaterialX's reference implementation defines them (module docstring)."""
    import MaterialX

    doc = MaterialX.createDocument()
    MaterialX.readFromXmlFile(doc, str(path))
    (shader,) = [n for n in doc.getNodes() if n.getCategory() == "standard_surface"]
    v = {i.getName(): i.getValue() for i in shader.getInputs()}
    t = mx_rotate(np.array([1.0, 0.0, 0.0]), 360.0 * v["specular_rotation"],
                  np.array([0.0, 0.0, 1.0]))
    r2 = min(max(v["specular_roughness"] ** 2, 1e-6), 1.0)
    aspect = math.sqrt(1.0 - min(max(v["specular_anisotropy"], 0.0), 0.98))
    ax, ay = min(r2 / aspect, 1.0), r2 * aspect
    assert v["metalness"] == 1.0, "this reading covers metals"
    color = v["base_color"]
    f0 = tuple(float(v["base"] * c) for c in (color[0], color[1], color[2]))
    return math.degrees(math.atan2(t[1], t[0])), ax, ay, f0  # type: ignore[return-value]


def test_the_issues_control_document_reads_as_the_issue_saw_it() -> None:
    # Issue 26: in MaterialX's GLSL renderer a document with specular_rotation 0.125 streaked
    # at 135 degrees, not 45: the reading used here must agree with that observation.
    t = mx_rotate(np.array([1.0, 0.0, 0.0]), 360 * 0.125, np.array([0.0, 0.0, 1.0]))
    assert math.degrees(math.atan2(t[1], t[0])) % 180 == pytest.approx(135.0)


@pytest.mark.parametrize("direction", [25.0, 88.0, 140.0])
def test_materialx_streaks_the_mtlx_like_gonio(tmp_path: Path, direction: float) -> None:
    p = Principled((0.9, 0.85, 0.8), 1.0, 0.5, 0.24, 0.03, direction)
    path = mtlx.write_mtlx(p, tmp_path / "m.mtlx", "brushed", {"specimen": "test"})
    tangent_deg, ax, ay, f0 = materialx_reading(path)
    lobe = bm.Rotated(bm.GGX(ax, ay, bm.SchlickFresnel(f0), "separable"),
                      math.radians(tangent_deg))
    flash = render.PointLight(0.0, 0.0)
    theirs = highlight(np.nan_to_num(render.render_sphere(lobe, flash, SIZE)))
    ours = highlight(np.nan_to_num(render.render_sphere(p.model(), flash, SIZE)))
    assert angle_between(ours.direction_deg, direction) < ANGLE_TOL_DEG, ours
    assert angle_between(theirs.direction_deg, ours.direction_deg) < ANGLE_TOL_DEG, (
        theirs, ours)
    assert theirs.major_px == pytest.approx(ours.major_px, rel=WIDTH_TOL)
    assert theirs.minor_px == pytest.approx(ours.minor_px, rel=WIDTH_TOL)
