"""bench_unseen's ``--black-level`` diagnostic lifts the sphere's pixels of a rendering by a
fraction of the reference's brightest pixel and leaves the background black (science.md
7.0.2)."""

from __future__ import annotations

from types import ModuleType

import numpy as np
import pytest

from gonio.brdf.pictures import appearance
from tests.unit.bench_import import import_bench


@pytest.fixture(scope="module")
def bench_unseen() -> ModuleType:
    return import_bench("bench_unseen")


def test_the_floor_is_added_to_the_sphere_only(bench_unseen: ModuleType) -> None:
    masks = appearance.drawn_masks()
    rng = np.random.default_rng(3)
    images = [np.where(d[..., None], rng.uniform(0, 5, (*d.shape, 3)), 0.0) for d in masks]
    lifted = bench_unseen.with_black_level(images, 1e-3, 40.0)
    for before, after, d in zip(images, lifted, masks, strict=True):
        assert np.array_equal(after[~d], np.zeros_like(after[~d]))
        np.testing.assert_allclose(after[d], before[d] + 0.04, rtol=0, atol=1e-12)


def test_no_floor_leaves_the_renderings_as_they_are(bench_unseen: ModuleType) -> None:
    images = [np.ones((4, 4, 3))]
    assert bench_unseen.with_black_level(images, 0.0, 7.0) is images


def test_the_floor_must_be_a_fraction(bench_unseen: ModuleType,
                                      capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        bench_unseen.main(["--black-level", "1.5", "--only", "aniso"])
    assert "give a fraction of the brightest pixel in [0, 1)" in capsys.readouterr().err
