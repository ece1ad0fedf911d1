"""MERL .binary: layout, index mapping and scales as the published reader defines them."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from gonio.brdf.materials.merl import read_merl_values
from gonio.brdf.models import analytic as bm
from gonio.export import merl


def _merl_index(theta_h: float, theta_d: float, phi_d: float) -> tuple[int, int, int]:
    """Bin of half/difference angles (radians), written out from the MERL reader's rules:
    theta_h non-linear (sqrt), theta_d and phi_d linear in 1 degree bins, phi_d mod pi."""
    i_h = 0 if theta_h <= 0 else min(89, int(math.sqrt(theta_h / (math.pi / 2) * 90 * 90)))
    i_d = min(89, max(0, int(theta_d / (math.pi / 2) * 90)))
    if phi_d < 0:
        phi_d += math.pi
    i_p = min(179, max(0, int(phi_d / math.pi * 180)))
    return i_h, i_d, i_p


def test_lambert_raw_numbers_follow_the_published_scales(tmp_path: Path) -> None:
    albedo = (0.3, 0.5, 0.7)
    p = merl.write_merl(bm.tabulate(bm.Lambert(albedo), np.float64), tmp_path / "l.binary")
    raw = p.read_bytes()
    assert np.frombuffer(raw[:12], "<i4").tolist() == [90, 90, 180]
    assert len(raw) == 12 + 3 * 90 * 90 * 180 * 8
    data = np.frombuffer(raw[12:], "<f8").reshape(3, 90, 90, 180)
    # R scale 1/1500, G 1.15/1500, B 1.66/1500: stored = (albedo / pi) / scale
    for c, s in enumerate((1 / 1500, 1.15 / 1500, 1.66 / 1500)):
        assert data[c, 10, 10, 10] == pytest.approx(albedo[c] / math.pi / s, rel=1e-12)
    assert (data[:, 89, 89, :] < 0).all()  # grazing light and view: below the horizon marker


def test_round_trip_and_index_mapping(tmp_path: Path) -> None:
    model = bm.LobeSum((bm.Lambert((0.2, 0.3, 0.4)),
                        bm.GGX(0.5, 0.5, bm.SchlickFresnel(0.04), "separable")))
    path = merl.write_merl(bm.tabulate(model, np.float64), tmp_path / "m.binary")
    back = read_merl_values(path)
    assert back.shape == (3, 90, 90, 180)
    rng = np.random.default_rng(1)
    checked = 0
    for _ in range(400):
        ti, to = rng.uniform(0, np.deg2rad(70), 2)
        pi_, po = rng.uniform(0, 2 * np.pi, 2)
        wi = np.array([math.sin(ti) * math.cos(pi_), math.sin(ti) * math.sin(pi_), math.cos(ti)])
        wo = np.array([math.sin(to) * math.cos(po), math.sin(to) * math.sin(po), math.cos(to)])
        from gonio.brdf.tables import geometry as geo

        th, _, td, pd = (float(x) for x in geo.directions_to_half_diff(wi, wo))
        idx = _merl_index(th, td, pd)
        got = back[(slice(None), *idx)]
        want = model.eval(wi[None], wo[None])[0]
        # 5 degree source grid and MERL's own bins: a smooth material agrees to a few percent
        np.testing.assert_allclose(got, want, rtol=0.08)
        checked += 1
    assert checked == 400


def test_bad_files_and_tables_are_refused(tmp_path: Path) -> None:
    with pytest.raises(merl.MerlError, match="cannot be read"):
        read_merl_values(tmp_path / "missing.binary")
    bad = tmp_path / "bad.binary"
    bad.write_bytes(np.array([90, 90, 90], "<i4").tobytes() + b"\0" * 64)
    with pytest.raises(merl.MerlError, match="dimensions"):
        read_merl_values(bad)
    bad.write_bytes(np.array([90, 90, 180], "<i4").tobytes() + b"\0" * 64)
    with pytest.raises(merl.MerlError, match="bytes"):
        read_merl_values(bad)
    mono = bm.tabulate(bm.Lambert(0.5, channels=("Y",)), np.float64)
    with pytest.raises(merl.MerlError, match="three channels"):
        merl.write_merl(mono, tmp_path / "y.binary")


def test_the_sidecar_of_a_result_without_twofold_symmetry_does_not_send_it_to_gltf() -> None:
    """A full-turn scan of a tilted facet (twofold asymmetry 0.136) was told "use the gltf,
    mtlx or table export to keep it" in its MERL sidecar, while its glTF and MaterialX
    exports warned that they show only the half-turn average: only the table and the
    factored model keep what differs at a half turn (docs/export.md, ``symmetry``)."""
    from gonio.brdf.materials import library

    table = bm.tabulate(library.get_material("brushed-metal-003"))  # anisotropic
    told = {}
    for asym in (0.0, 0.136):
        side = merl.merl_sidecar(table, {"symmetry": {"twofold_asymmetry": asym}})
        told[asym] = " ".join(side["warnings"])
    assert "use the gltf, glb, mtlx or table export" in told[0.0]
    assert "use the gltf, glb, mtlx or table export" not in told[0.136], told[0.136]
    assert "'table' or 'factored' export" in told[0.136] and "not twofold" in told[0.136]
