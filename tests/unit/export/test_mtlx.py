"""MaterialX export of principled parameters, validated against MaterialX's own standard library."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from gonio.brdf.models.principled import Principled
from gonio.export import mtlx

BRUSHED = Principled((0.9, 0.8, 0.6), 1.0, 0.5, 0.40, 0.10, 30.0)
PLASTIC = Principled((0.6, 0.2, 0.1), 0.0, 0.8, 0.09, 0.09, 0.0)
PROV = {"job_id": 7, "specimen": "felt", "factored_fit": {"rel_mse": 0.02}}


def mx_rotate(v: np.ndarray, amount_deg: float, axis: np.ndarray) -> np.ndarray:
    """MaterialX's ``rotate3d`` as its reference implementation defines it (genglsl and genosl
    ``mx_rotate_vector3``: Rodrigues' formula with the cross product reversed, "MaterialX
    follows v' = v * M"), written here from that definition."""
    a = math.radians(amount_deg)
    axis = axis / np.linalg.norm(axis)
    return np.asarray(v * math.cos(a) + np.cross(v, axis) * math.sin(a)
                      + axis * np.dot(axis, v) * (1 - math.cos(a)))


def test_mtlx_validates_and_maps_parameters(tmp_path: Path) -> None:
    import MaterialX

    path = mtlx.write_mtlx(BRUSHED, tmp_path / "b.mtlx", "brushed steel #1", PROV)
    doc = MaterialX.createDocument()
    MaterialX.readFromXmlFile(doc, str(path))
    lib = MaterialX.createDocument()
    MaterialX.loadLibraries(
        MaterialX.getDefaultDataLibraryFolders(), MaterialX.getDefaultDataSearchPath(), lib
    )
    doc.setDataLibrary(lib)
    ok, msg = doc.validate()
    assert ok, msg
    (shader,) = doc.getNodes("standard_surface") or [
        n for n in doc.getNodes() if n.getCategory() == "standard_surface"]
    value = {i.getName(): i.getValue() for i in shader.getInputs()}
    # MaterialX roughness_anisotropy: alpha_x = r^2 / sqrt(1 - a), alpha_y = r^2 sqrt(1 - a)
    r, a = value["specular_roughness"], value["specular_anisotropy"]
    assert r * r / math.sqrt(1 - a) == pytest.approx(0.40, rel=1e-5)  # stored as float32
    assert r * r * math.sqrt(1 - a) == pytest.approx(0.10, rel=1e-5)
    # MaterialX's rotate3d (stdlib mx_rotate_vector3): v c + (v x axis) s + axis (axis.v)(1-c),
    # which turns the tangent x about the normal z clockwise; the result must sit at +30 deg.
    t = mx_rotate(np.array([1.0, 0.0, 0.0]), 360 * value["specular_rotation"],
                  np.array([0.0, 0.0, 1.0]))
    assert math.degrees(math.atan2(t[1], t[0])) % 180 == pytest.approx(30.0, abs=1e-3)
    assert value["metalness"] == 1.0
    material, _openpbr = [n for n in doc.getNodes() if n.getCategory() == "surfacematerial"]
    assert json.loads(material.getDocString())["job_id"] == 7
    assert material.getAttribute("gonio_specimen") == "felt"


def test_mtlx_dielectric_ior_from_specular() -> None:
    inputs = mtlx.standard_surface_inputs(PLASTIC)
    ior = inputs["specular_IOR"]
    assert isinstance(ior, float)
    assert ((ior - 1) / (ior + 1)) ** 2 == pytest.approx(0.08 * 0.8)  # Fresnel at normal
    with pytest.raises(mtlx.MtlxError, match="three channels"):
        mtlx.standard_surface_inputs(Principled((0.5,), 0.0, 0.5, 0.2, 0.2, 0.0, ("Y",)))


def test_mtlx_specular_strength_round_trips(tmp_path: Path) -> None:
    """A strong, weighted dielectric layer: ``specular_IOR`` is the index whose
    normal-incidence Fresnel reflectance ``((n - 1)/(n + 1))^2`` is the level 0.88 (IOR 15.6,
    past the input's soft maximum of 3, which validation allows), ``specular`` the weight 0.6,
    so MaterialX's dielectric layer reflects ``weight F(ior)``: 0.6 x 0.88 at normal incidence
    as in gonio's model. The written document reads back to the same parameters."""
    coated = Principled((0.45, 0.09, 0.09), 0.0, 11.0, 0.35, 0.06, 120.0, specular_weight=0.6)
    inputs = mtlx.standard_surface_inputs(coated)
    ior = float(inputs["specular_IOR"])  # type: ignore[arg-type]
    assert ((ior - 1) / (ior + 1)) ** 2 == pytest.approx(0.88)
    assert inputs["specular"] == pytest.approx(0.6)
    assert inputs["specular"] * ((ior - 1) / (ior + 1)) ** 2 == pytest.approx(coated.f0[0])
    for p in (BRUSHED, PLASTIC, coated):
        path = mtlx.write_mtlx(p, tmp_path / "c.mtlx", "coated", PROV)  # validated
        back = mtlx.principled_from_inputs(mtlx.read_standard_surface(path.read_text()))
        assert back.specular_weight == pytest.approx(p.specular_weight, rel=1e-6)
        assert back.dielectric_f0 == pytest.approx(p.dielectric_f0, rel=1e-5)
        assert (back.alpha_t, back.alpha_b) == pytest.approx((p.alpha_t, p.alpha_b), rel=1e-5)
        assert back.direction_deg == pytest.approx(p.direction_deg, abs=1e-3)
        assert np.allclose(back.base_color, p.base_color, atol=1e-6)
    with pytest.raises(mtlx.MtlxError, match="tint"):
        mtlx.principled_from_inputs({**inputs, "specular_color": (1.0, 0.5, 0.5)})
