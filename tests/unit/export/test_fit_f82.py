"""The F82 tint of a metal's fit (the MaterialX export's open_pbr_surface, issue 26)."""

from __future__ import annotations

import numpy as np
import pytest

from gonio.brdf.models import analytic as bm
from gonio.brdf.models.principled import Principled, PrincipledError, fit_f82_tint
from gonio.export import judge

TINT = (0.55, 0.7, 0.9)
SHAPE = ((0.92, 0.9, 0.85), 1.0, 0.5, 0.25, 0.08, 40.0)


def test_tint_of_a_dipping_metal_is_recovered_from_its_table() -> None:
    table = bm.tabulate(Principled(*SHAPE, f82_tint=TINT).model(), np.float64)
    got = fit_f82_tint(table, Principled(*SHAPE))
    assert got == pytest.approx(TINT, abs=0.02)
    # a Schlick metal's table gives a white tint
    plain = bm.tabulate(Principled(*SHAPE).model(), np.float64)
    assert fit_f82_tint(plain, Principled(*SHAPE)) == pytest.approx((1, 1, 1), abs=0.02)
    with pytest.raises(PrincipledError, match="metal"):
        fit_f82_tint(table, Principled((0.5, 0.5, 0.5), 0.0, 0.5, 0.2, 0.2, 0.0))


def test_fit_f82_keeps_the_tint_when_the_table_says_so_and_leaves_dielectrics() -> None:
    table = bm.tabulate(Principled(*SHAPE, f82_tint=TINT).model(), np.float64)
    schlick = Principled(*SHAPE)
    got = judge.fit_f82(table, schlick)
    assert got.f82_tint == pytest.approx(TINT, abs=0.02)
    assert got.metrics["log_rmse"] < got.metrics["schlick_log_rmse"]
    # the judge's views (light within 55 degrees of the view) barely tell them apart: the
    # Schlick fit of the tinted table renders within 0.01 of it, the tinted one no farther
    assert got.metrics["schlick_rendered"] < 0.01
    assert got.metrics["rendered"]["value"] <= (
        got.metrics["schlick_rendered"] + judge.F82_RENDER_SLACK)
    plastic = Principled((0.6, 0.2, 0.1), 0.0, 0.5, 0.1, 0.1, 0.0)
    assert judge.fit_f82(table, plastic) is plastic
