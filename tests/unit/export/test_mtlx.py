"""MaterialX export of principled parameters, validated against MaterialX's own standard library."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from gonio.brdf.models.principled import Principled
from gonio.export import mtlx

BRUSHED = Principled((0.9, 0.8, 0.6), 1.0, 0.5, 0.40, 0.10, 30.0)
PLASTIC = Principled((0.6, 0.2, 0.1), 0.0, 0.8, 0.09, 0.09, 0.0)
PROV = {"job_id": 7, "specimen": "felt", "factored_fit": {"rel_mse": 0.02}}


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
    assert value["specular_rotation"] * 360 == pytest.approx(30.0, rel=1e-5)
    assert value["metalness"] == 1.0
    (material,) = [n for n in doc.getNodes() if n.getCategory() == "surfacematerial"]
    assert json.loads(material.getDocString())["job_id"] == 7


def test_mtlx_dielectric_ior_from_specular() -> None:
    inputs = mtlx.standard_surface_inputs(PLASTIC)
    ior = inputs["specular_IOR"]
    assert isinstance(ior, float)
    assert ((ior - 1) / (ior + 1)) ** 2 == pytest.approx(0.08 * 0.8)  # Fresnel at normal
    with pytest.raises(mtlx.MtlxError, match="three channels"):
        mtlx.standard_surface_inputs(Principled((0.5,), 0.0, 0.5, 0.2, 0.2, 0.0, ("Y",)))
