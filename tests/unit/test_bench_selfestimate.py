"""bench_selfestimate's in-plane candidate term (science.md 7.1.1): ``k s_in cv_log_error``."""

from __future__ import annotations

from types import ModuleType

import pytest

from tests.unit.bench_import import import_bench


@pytest.fixture(scope="module")
def bench() -> ModuleType:
    return import_bench("bench_selfestimate")


def test_the_term_is_the_share_times_the_leave_one_pair_out_error(bench: ModuleType) -> None:
    assert bench.in_plane_term(0.5, 0.4, 0.8) == pytest.approx(0.16)
    # The share is clipped to 0..1; a missing error or a zero coefficient adds nothing.
    assert bench.in_plane_term(1.7, 0.4, 0.8) == pytest.approx(0.32)
    assert bench.in_plane_term(-0.2, 0.4, 0.8) == 0.0
    assert bench.in_plane_term(1.0, float("nan"), 0.8) == 0.0
    assert bench.in_plane_term(1.0, 0.4, 0.0) == 0.0


def test_the_grid_and_the_fresh_set_are_as_written_down(bench: ModuleType) -> None:
    assert bench.IN_PLANE_GRID[0] == 0.0 and bench.IN_PLANE_GRID[-1] == pytest.approx(1.5)
    assert len(bench.FRESH_INPLANE) == 16
    assert not {n for n, *_ in bench.FRESH_INPLANE} & {n for n, *_ in bench.FRESH}
