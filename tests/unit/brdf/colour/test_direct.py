"""Instrument geometries a scan measured: the report uses the pair's readings there
(gonio.brdf.colour.direct)."""

from __future__ import annotations

import csv
import io
import math

import numpy as np
import pytest

from gonio.brdf.colour.conditions import ColourError
from gonio.brdf.colour.direct import ScanReadings
from gonio.brdf.colour.report import colour_report
from gonio.brdf.tables import geometry as geo
from gonio.brdf.tables.table import from_function

ALPHA_DEG = np.arange(8) * 22.5  # 8 stage angles over half a turn


def glossy(wi: np.ndarray, wo: np.ndarray, aniso: bool = False) -> np.ndarray:
    """A grey diffuse base plus a lobe about the specular direction narrower than the table's
    5 degree cells (1/sr, one channel); ``aniso``: a lobe wider along y (10 degrees) than
    along x (6 degrees), as a brushed metal's."""
    h = wi + wo
    h = h / np.linalg.norm(h, axis=-1, keepdims=True)
    if aniso:
        lobe = np.exp(-(h[..., 0] ** 2 / 0.01 + h[..., 1] ** 2 / 0.03))
    else:
        lobe = np.exp(-(1 - h[..., 2] ** 2) / 0.004)
    return (0.3 / np.pi + 20.0 * lobe)[..., None]


def in_plane(incidence: float, aspecular: float, azimuth: float = 0.0
             ) -> tuple[np.ndarray, np.ndarray]:
    """Light and sensor of an instrument geometry (ASTM E2194), plane of incidence at
    ``azimuth`` degrees."""
    ti, tv, p = (math.radians(x) for x in (incidence, incidence - aspecular, azimuth))
    return (np.array([math.sin(ti) * math.cos(p), math.sin(ti) * math.sin(p), math.cos(ti)]),
            np.array([-math.sin(tv) * math.cos(p), -math.sin(tv) * math.sin(p), math.cos(tv)]))


def scan_of(fn, geoms: list[tuple[float, float]], lab_azimuth_deg: float) -> ScanReadings:
    """Pairs at ``geoms`` mounted with the plane of incidence at ``lab_azimuth_deg`` in the lab,
    read exactly at every stage angle (the stage turns the specimen by +alpha)."""
    li, so = zip(*(in_plane(i, a, lab_azimuth_deg) for i, a in geoms), strict=True)
    L, S = np.stack(li), np.stack(so)
    vals = np.stack([fn(geo.lab_to_specimen(L, math.radians(a)),
                        geo.lab_to_specimen(S, math.radians(a))) for a in ALPHA_DEG], axis=1)
    return ScanReadings(L, S, ALPHA_DEG, vals)


def test_measured_geometries_read_the_specimen_not_the_table() -> None:
    """For an isotropic lobe the readings at 45as15 and 15as-5 are the BRDF there (the formula
    itself); the table, whose cells are wider than the lobe, is off by far more."""
    table = from_function(glossy, ["Y"], "gloss")
    scan = scan_of(glossy, [(45, 15), (15, -5)], lab_azimuth_deg=37.0)
    plain = colour_report(table, None, instruments=["MA98"])
    direct = colour_report(table, None, instruments=["MA98"], scan=scan)
    names = [g.name for g in direct.geometries]
    assert [n for n, m in zip(names, direct.measured, strict=True) if m] == ["45as15", "15as-5"]
    for name in ("45as15", "15as-5"):
        k = names.index(name)
        g = direct.geometries[k]
        li, vi = in_plane(g.incidence_deg, g.aspecular_deg)
        truth = math.pi * float(glossy(li[None], vi[None])[0, 0])
        assert direct.reflectance[k, 0] == pytest.approx(truth, rel=1e-9)
        # The test means something: the table alone misses it by more than 5 %.
        assert abs(plain.reflectance[k, 0] / truth - 1) > 0.05
    # The geometries no pair measured are the table's, unchanged.
    other = [k for k, m in enumerate(direct.measured) if not m]
    np.testing.assert_array_equal(direct.reflectance[other], plain.reflectance[other])
    assert direct.as_dict()["measured"] == list(direct.measured)
    # The CSV carries the same flags, geometry by geometry; a report without a scan says none.
    rows = list(csv.DictReader(io.StringIO(direct.csv())))
    assert [r["source"] for r in rows] == [
        "pair" if n in ("45as15", "15as-5") else "table" for n in names]
    assert {r["source"] for r in csv.DictReader(io.StringIO(plain.csv()))} == {"table"}


@pytest.mark.parametrize("azimuth", [0.0, 30.0, 90.0])
def test_anisotropic_lobe_is_read_at_the_wanted_azimuth(azimuth: float) -> None:
    """The pair read the anisotropic lobe at 8 specimen azimuths; the report at another azimuth
    takes the table's azimuthal shape scaled to those readings (a constant and the second
    harmonic in the stage angle): within 2 % of the formula; along the brushing (azimuth 0)
    the table alone is off by more than 5 %."""
    fn = lambda wi, wo: glossy(wi, wo, aniso=True)  # noqa: E731
    table = from_function(fn, ["Y"], "aniso")
    scan = scan_of(fn, [(45, 15)], lab_azimuth_deg=10.0)
    plain = colour_report(table, None, instruments=["MA68"], azimuths_deg=[azimuth])
    direct = colour_report(table, None, instruments=["MA68"], azimuths_deg=[azimuth],
                           scan=scan)
    k = [g.name for g in direct.geometries].index("45as15")
    li, vi = in_plane(45, 15, azimuth)
    truth = math.pi * float(fn(li[None], vi[None])[0, 0])
    assert direct.measured[k]
    assert abs(direct.reflectance[k, 0] / truth - 1) < 0.02
    if azimuth == 0.0:
        assert abs(plain.reflectance[k, 0] / truth - 1) > 0.05


def test_a_pair_off_the_geometry_by_more_than_the_tolerance_is_not_used() -> None:
    table = from_function(glossy, ["Y"], "gloss")
    scan = scan_of(glossy, [(45, 15.6), (30, 0)], lab_azimuth_deg=0.0)
    rep = colour_report(table, None, instruments=["MA98"], scan=scan)
    assert not any(rep.measured)


def test_readings_of_the_wrong_shape_are_refused() -> None:
    with pytest.raises(ColourError, match=r"\(n, r, C\) values"):
        ScanReadings(np.zeros((2, 3)), np.zeros((2, 3)), ALPHA_DEG, np.zeros((2, 7, 1)))
