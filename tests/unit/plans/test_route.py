"""Route ordering of the stage angles (gonio.plans.route)."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from gonio.plans.route import order_for_travel
from gonio.rigdescription import RigDescription


def _limited(desc: RigDescription, lo: float, hi: float) -> RigDescription:
    return desc.model_copy(update={"stage_min_deg": lo, "stage_max_deg": hi})


def test_order_is_increasing_and_starts_near_the_stage(desc: RigDescription) -> None:
    angles = [0, 90, 180, 270]
    route = order_for_travel(angles, 100.0, desc)
    assert all(b > a for a, b in itertools.pairwise(route))
    # Back 10 deg to 90, then up to 360 (280 deg) beats 180 -> 450 (350 deg).
    assert route == pytest.approx([90.0, 180.0, 270.0, 360.0])
    # From 175 the route starting ahead at 180 is shorter.
    assert order_for_travel(angles, 175.0, desc)[0] == pytest.approx(180.0)
    assert sorted(a % 360 for a in route) == angles
    # A stage that cannot pass 360 must go back to the lowest angle first.
    route = order_for_travel(angles, 100.0, _limited(desc, 0.0, 300.0))
    assert route == [0, 90, 180, 270]


def _brute_force_route(angles: list[float], current: float, rig: RigDescription,
                       backlash: float) -> list[float]:
    """The documented rule, written out the slow way: build every cyclic route from every
    stage position of its first angle, keep those inside the limits, pick the least travel."""
    base = sorted({round(a % 360.0, 9) for a in angles})
    best: tuple[float, list[float]] | None = None
    for s in range(len(base)):
        cyc = base[s:] + base[:s]
        for m in range(-5, 6):
            first = cyc[0] + 360.0 * m
            if not rig.stage_min_deg - 1e-9 <= first <= rig.stage_max_deg + 1e-9:
                continue
            if abs(first - current) > 720.0 + backlash:
                continue
            route = [first]
            for a in cyc[1:]:
                route.append(route[-1] + (a - route[-1]) % 360.0)
            if route[-1] > rig.stage_max_deg + 1e-9:
                continue
            if current <= first:
                cost = route[-1] - current
            else:
                pre = max(rig.stage_min_deg, first - backlash)
                cost = (current - pre) + (route[-1] - pre)
            if best is None or cost < best[0] - 1e-9:
                best = (cost, route)
    assert best is not None
    return best[1]


def test_linear_ordering_matches_the_brute_force_rule(desc: RigDescription) -> None:
    rng = np.random.default_rng(7)
    for trial in range(200):
        lo, hi = [(-360.0, 720.0), (0.0, 360.0), (-180.0, 540.0), (0.0, 300.0)][trial % 4]
        rig = _limited(desc, lo, hi)
        n = int(rng.integers(1, 12))
        angles = list(rng.uniform(0, 300 if hi == 300 else 360, n).round(2))
        current = float(rng.uniform(lo, hi))
        backlash = float(rng.choice([0.0, 2.0]))
        got = order_for_travel(angles, current, rig, backlash)
        assert got == pytest.approx(_brute_force_route(angles, current, rig, backlash))
