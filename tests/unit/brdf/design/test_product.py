"""Tests of the product-rig design: every light with every sensor (gonio.brdf.design.product)."""

from __future__ import annotations

import numpy as np
import pytest

from gonio.brdf.design.errors import DesignError
from tests.unit.brdf.design.test_pairs import _grid_basis


def test_product_rig_respects_constraints_and_reports_its_kappa() -> None:
    from gonio.brdf.design.constraints import ConeExclusion, RigConstraints
    from gonio.brdf.design.pairs import geometry_design
    from gonio.brdf.design.placement import check_devices
    from gonio.brdf.design.product import design_product_rig
    from gonio.brdf.tables import geometry as geo

    basis = _grid_basis()
    c = RigConstraints(max_elevation_deg=70.0, min_device_distance_deg=15.0,
                       exclusions=(ConeExclusion(0.0, 0.0, 12.0),))
    d = design_product_rig(basis, 2, 3, c, h=3, starts=2, seed=0)
    assert d.n_pairs == 6 and d.pairs.tolist() == [[a, b] for a in range(2) for b in range(3)]
    li = geo.spherical_to_direction(*np.deg2rad(d.lights_deg).T)
    se = geo.spherical_to_direction(*np.deg2rad(d.sensors_deg).T)
    assert check_devices(li, se, c) == []
    again = geometry_design(basis, "x", li, se, d.pairs)
    assert again.kappa == pytest.approx(d.kappa, rel=1e-9)
    # Better than where it started: random feasible rigs of the same size, on average.
    rng = np.random.default_rng(5)
    from gonio.brdf.design.product import _random_rig, product_kappa

    grid_t, grid_p = np.meshgrid(np.deg2rad(np.arange(15, 71, 5)), np.deg2rad(np.arange(0, 360, 5)))
    gdirs = geo.spherical_to_direction(grid_t.ravel(), grid_p.ravel())
    kinds = np.array([True, True, False, False, False])
    rigs = [_random_rig(gdirs, kinds, c, rng) for _ in range(10)]
    ks = [product_kappa(basis.rows_at, gdirs[r][None, :2], gdirs[r][None, 2:])[0]
          for r in rigs if r is not None]
    assert d.kappa <= np.median(ks)


def test_product_rig_errors() -> None:
    from gonio.brdf.design.constraints import RigConstraints
    from gonio.brdf.design.errors import FeasibilityError
    from gonio.brdf.design.product import design_product_rig

    basis = _grid_basis()
    with pytest.raises(DesignError, match="at least one light and one sensor"):
        design_product_rig(basis, 0, 3, RigConstraints())
    crowded = RigConstraints(max_elevation_deg=10.0, min_device_distance_deg=15.0)
    with pytest.raises(FeasibilityError, match="could not place 3 lights and 3 sensors"):
        design_product_rig(basis, 3, 3, crowded, starts=1)
