"""The pair design type: independent pairs from a placement, and the lab directions of each
pair of a shared-device (product) design."""

from __future__ import annotations

import numpy as np

from gonio.brdf.design.pairdesign import OBJECTIVES, PairDesign
from gonio.brdf.design.placement import Placement


def test_objectives_are_listed_in_the_documented_order() -> None:
    # docs/design.md lists them in this order: the condition number, then the expected error
    assert OBJECTIVES == ("kappa", "posterior")


def test_independent_pairs_give_each_light_its_own_sensor() -> None:
    lab = np.array([[45.0, 0.0, 30.0, 180.0], [60.0, 90.0, 10.0, 270.0],
                    [20.0, 200.0, 70.0, 20.0]])
    placement = Placement(cells=np.zeros((3, 3)), ph_lab=np.array([0.0, 1.0, 2.0]),
                          lab_deg=lab, min_distance_deg=12.5)
    d = PairDesign.independent("optimized", placement, kappa=3.5)
    assert d.n_pairs == 3
    assert d.pairs.tolist() == [[0, 0], [1, 1], [2, 2]]
    np.testing.assert_array_equal(d.lab_deg, lab)  # the placement's directions, pair by pair
    assert (d.kappa, d.min_distance_deg, d.objective, d.search) == (3.5, 12.5, None, None)


def test_a_product_design_repeats_shared_devices_per_pair() -> None:
    """Two lights and two sensors, every light with every sensor: four rows of lab_deg."""
    lights = np.array([[45.0, 0.0], [30.0, 90.0]])
    sensors = np.array([[0.0, 0.0], [60.0, 180.0]])
    pairs = np.array([[0, 0], [0, 1], [1, 0], [1, 1]], dtype=np.intp)
    d = PairDesign("product", np.zeros((4, 3)), np.zeros(4), lights, sensors, pairs, 2.0, 30.0)
    assert d.n_pairs == 4
    assert d.lab_deg.tolist() == [[45, 0, 0, 0], [45, 0, 60, 180], [30, 90, 0, 0],
                                  [30, 90, 60, 180]]
