"""Tests of the held-out expected error of a design (gonio.brdf.design.heldout)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from gonio.brdf.design import heldout
from gonio.brdf.reconstruction.reconstruct import reconstruct
from gonio.brdf.reconstruction.samples import NoiseModel, simulate_samples
from gonio.brdf.tables import metrics
from tests.unit.brdf.reconstruction.test_basis import small_basis, small_library
from tests.unit.brdf.reconstruction.test_reconstruct import grid_pairs


@pytest.fixture()
def tiny_panel(monkeypatch: pytest.MonkeyPatch) -> list:  # type: ignore[type-arg]
    b = small_basis()
    lib = small_library()
    synth, meas = lib[:2], [(lib[2], b)]
    monkeypatch.setattr(heldout, "_panel", lambda: (b, synth, meas))
    return [b, synth, meas]


@pytest.mark.parametrize("span_deg", [180.0, 360.0])
def test_expected_error_is_the_panel_mean_of_simulated_scans(
        tiny_panel: list, span_deg: float) -> None:  # type: ignore[type-arg]
    b, synth, meas = tiny_panel
    cells, ph = grid_pairs(8, seed=1)
    got = heldout.heldout_log_rmse(cells, ph, rotations=6, seed=4, span_deg=span_deg)
    alpha = np.deg2rad(np.arange(6) * span_deg / 6)  # 6 uniform angles over the arc
    want = []
    for k, t in enumerate([*synth, meas[0][0]]):
        vals = simulate_samples(t, cells, ph, alpha, noise=NoiseModel(0.01, seed=4 + k))
        want.append(metrics.log_rmse(reconstruct(b, cells, ph, alpha, vals).table, t))
    assert got.log_rmse == pytest.approx(np.mean(want))
    assert got.synthetic == pytest.approx(np.mean(want[:2]))
    assert got.measured == pytest.approx(want[2])
    assert set(got.per_material) == {t.name for t in [*synth, meas[0][0]]}


def test_choose_design_keeps_the_lowest_expected_error(tiny_panel: list) -> None:  # type: ignore[type-arg]
    designs = {s: SimpleNamespace(cells=grid_pairs(6, seed=s)[0], ph_lab=grid_pairs(6, seed=s)[1],
                                  kappa=float(s)) for s in range(3)}
    best, err, table = heldout.choose_design(lambda s: designs[s], range(3), rotations=4)
    assert [row[0] for row in table] == [0, 1, 2]
    assert err.log_rmse == pytest.approx(min(row[2] for row in table))
    assert best is designs[int(np.argmin([row[2] for row in table]))]
