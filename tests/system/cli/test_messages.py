"""Messages a lab meets on its first day say what was wrong and which command helps (issue 27,
item 7): a misspelt material, a sensor's exposure range, `gonio keys list` as the README
writes it."""

from __future__ import annotations

import pytest

from gonio.brdf.materials.library import FAMILY_COUNTS, library_specs
from gonio.cli import main


def test_a_misspelt_material_points_to_the_command_that_lists_materials(
    capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["scan", "--sim", "--material", "velvett", "--dry-run", "-o", "/dev/null"]) == 2
    err = capsys.readouterr().err
    assert "no library material named 'velvett'" in err, err
    assert "'gonio library list' lists them" in err and "library_specs" not in err, err
    # And that command lists them: every synthetic name is in one of its ranges.
    assert main(["library", "list"]) == 0
    out = capsys.readouterr().out
    assert f"synthetic library materials ({len(library_specs())};" in out, out
    for family, n in FAMILY_COUNTS.items():
        assert f"{family}-000 .. {family}-{n - 1:03d}" in out, out
    names = {s.name for s in library_specs()}
    assert names == {f"{f}-{i:03d}" for f, n in FAMILY_COUNTS.items() for i in range(n)}


def test_an_exposure_out_of_a_sensors_range_reads_as_english(
    capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["scan", "--rig", "deploy/rig.example.toml", "--exposure", "1000",
                 "--dry-run", "-o", "/dev/null"]) == 2
    err = capsys.readouterr().err
    assert "outside the exposure range of sensor 'S1'" in err, err
    assert "''s" not in err


def test_keys_list_without_a_file_says_which_file_it_wants(
    capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["keys", "list"]) == 2
    err = capsys.readouterr().err
    assert "gonio keys list --keys-file api-keys" in err, err
    assert "one of the arguments" not in err
    assert main(["keys", "new", "lab"]) == 2
    assert "gonio keys new lab --keys-file api-keys" in capsys.readouterr().err
