"""gonio.wording: a count before its noun reads as English."""

from __future__ import annotations

from gonio.wording import counted


def test_one_is_singular_and_every_other_count_plural() -> None:
    assert counted(1, "stage angle") == "1 stage angle"
    assert counted(8, "stage angle") == "8 stage angles"
    assert counted(0, "pair") == "0 pairs"
    assert counted(1, "reading") == "1 reading"


def test_an_irregular_plural_is_given() -> None:
    assert counted(2, "job is", "jobs are") == "2 jobs are"
    assert counted(1, "job is", "jobs are") == "1 job is"
