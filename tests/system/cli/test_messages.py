"""Messages a lab meets on its first day say what was wrong and which command helps (issue 27,
item 7): a misspelt material, a sensor's exposure range, `gonio keys list` as the README
writes it."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import pytest

from gonio.brdf.materials.library import (
    ASYMMETRIC_FAMILY_COUNTS,
    FAMILY_COUNTS,
    library_specs,
)
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
    # The message names the families without twofold symmetry too, which --material takes:
    # the list has them (it had not), and says the shipped measured names are not such names.
    for family, n in ASYMMETRIC_FAMILY_COUNTS.items():
        assert f"{family}" in err and f"{family}-000 .. {family}-{n - 1:03d}" in out, out
    assert "not --material names" in out, out
    last = f"pile-{ASYMMETRIC_FAMILY_COUNTS['pile'] - 1:03d}"
    assert main(["scan", "--sim", "--material", last, "--dry-run", "-o", "/dev/null"]) == 0


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


def test_design_says_what_its_expected_error_assumes(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    # Issue 27 item 5: a design promising 0.012 "inside the basis" beside a scan reporting
    # 0.058 on an anisotropic material, with nothing to say which numbers compare.
    # The wording and the fragment are under test, not the held-out panel's own numbers
    # (tests/unit/brdf/design/test_heldout.py): a small panel spares the real one's build, a
    # basis from the whole library (more than a minute of CPU on a fresh cache).
    from gonio.brdf.design import heldout
    from tests.unit.brdf.reconstruction.test_basis import small_basis, small_library

    small, lib = small_basis(), small_library()
    monkeypatch.setattr(heldout, "_panel", lambda: (small, lib[:2], [(lib[2], small)]))
    frag = tmp_path / "geometry.toml"
    assert main(["design", "--preset", "ma98", "-o", str(frag)]) == 0
    out = capsys.readouterr().out
    assert "(inside the basis: on the materials it was learnt from, a best case" in out, out
    held = [ln for ln in out.splitlines() if ln.startswith("expected log_rmse on held-out")]
    assert len(held) == 1, out
    value = held[0].split(": ", 1)[1].split()[0]
    assert "what it assumes: a calibrated scan (1/sr) with 1 % reading noise" in out
    assert "set a scan's predicted_log_rmse" in out
    # The fragment keeps the number to compare a scan with, and what it assumed.
    header = frag.read_text().split("\n[", 1)[0]
    assert f"held-out materials {value} at 8 uniform rotations over 180 deg" in header, header
    # ... and as the [design] table that rig apply-design carries into the rig config, so each
    # scan compares its predicted_log_rmse with it (gonio.designgap).
    from gonio.rigdesign import load_fragment

    design = load_fragment(frag).design
    assert design is not None
    assert design.expected_log_rmse == pytest.approx(float(value), abs=5e-5)
    assert (design.rotations, design.span_deg, design.noise, design.calibrated) == (
        8, 180.0, 0.01, True)
    assert design.pairs == 19  # MA98's pairs


def test_a_taken_port_is_refused_before_anything_starts_saying_what_to_do(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    # A second `gonio serve --sim` (or any program on 8600) made uvicorn stop after the service
    # and the simulated rig had started: "[Errno 98] ... address already in use", status 3.
    import socket

    monkeypatch.setenv("HOME", str(tmp_path))
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        assert main(["serve", "--sim", "--throwaway", "--port", str(port)]) == 2
    out, err = capsys.readouterr()
    assert f"port {port} on 127.0.0.1 is in use by another program" in err, err
    assert "--port N" in err and "--port 0" in err, err
    assert "simulated rig" not in out, out  # nothing was started


def test_an_output_that_cannot_be_written_is_refused_before_the_scan(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # `gonio scan -o` into a folder that could not be written measured the whole scan and only
    # then failed to copy the result, with "No such file or directory; check that the
    # directory exists" about a folder that existed, and no word that the result was kept.
    from gonio.sim.rig import SimRigOptions, start_sim_rig

    blocker = tmp_path / "a-file"
    blocker.write_text("")
    out = blocker / "felt.h5"
    folder = tmp_path / "results"
    folder.mkdir()
    rig, data = tmp_path / "rig.toml", tmp_path / "data"
    with start_sim_rig(SimRigOptions(time_scale=10.0, settle_s=0.0, config_path=rig)):
        argv = ["scan", "--no-export-fits", "--rig", str(rig), "--rotations", "2",
                "--accept-uncalibrated", "--no-progress", "--data-dir", str(data)]
        assert main([*argv, "-o", str(out)]) == 2
        err = capsys.readouterr().err
        assert f"-o {out}: cannot write into {blocker}" in err, err
        assert "nothing was measured" in err, err
        assert not data.exists()  # no job store, no job
        assert main([*argv, "-o", str(folder)]) == 2
        assert f"-o {folder} is a folder" in capsys.readouterr().err
    assert list(folder.iterdir()) == []  # the probe left nothing behind


def test_an_existing_output_is_refused_unless_overwrite_says_to_replace_it(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # `gonio scan -o felt.h5` run again (the shell's history, a second specimen with the same
    # name) replaced yesterday's result without a word once the new scan ended.
    from gonio.sim.rig import SimRigOptions, start_sim_rig

    old = tmp_path / "felt.h5"
    old.write_bytes(b"yesterday's result")
    white = tmp_path / "white.h5"
    white_cal = tmp_path / "white.calibration.json"
    white_cal.write_text('{"yesterday": true}')
    rig, data = tmp_path / "rig.toml", tmp_path / "data"
    with start_sim_rig(SimRigOptions(time_scale=10.0, settle_s=0.0, config_path=rig)):
        argv = ["scan", "--no-export-fits", "--rig", str(rig), "--rotations", "2",
                "--accept-uncalibrated", "--no-progress", "--data-dir", str(data)]
        assert main([*argv, "-o", str(old)]) == 2
        err = capsys.readouterr().err
        assert f"{old} already exists" in err and "--overwrite" in err, err
        assert "nothing was measured" in err, err
        assert not data.exists()  # no job store, no job
        assert old.read_bytes() == b"yesterday's result"
        # A calibration writes its calibration beside the result: that file is checked too.
        assert main([*argv, "--white-reference", "0.99", "-o", str(white)]) == 2
        err = capsys.readouterr().err
        assert f"{white_cal} already exists" in err, err
        assert not data.exists() and not white.exists()
        assert white_cal.read_text() == '{"yesterday": true}'
        # A pipe, or a link to a missing file: the result would be renamed onto it (or a
        # FIFO refuse the copy only when the scan has ended).
        import os

        fifo = tmp_path / "pipe.h5"
        os.mkfifo(fifo)
        assert main([*argv, "-o", str(fifo)]) == 2
        assert f"-o {fifo} is not a regular file" in capsys.readouterr().err
        dangling = tmp_path / "link.h5"
        dangling.symlink_to(tmp_path / "nowhere.h5")
        assert main([*argv, "-o", str(dangling)]) == 2
        assert f"-o {dangling} is a link to a missing file" in capsys.readouterr().err
        assert not data.exists() and fifo.exists() and dangling.is_symlink()
        # A dry run writes nothing, so it is not refused.
        assert main([*argv, "--dry-run", "-o", str(old)]) == 0
        capsys.readouterr()
        # --overwrite: the scan runs and its result replaces the old file.
        assert main([*argv, "--overwrite", "-o", str(old)]) == 0
        # A file that appears at -o while the scan runs (a second scan given the same -o
        # ended first) is not replaced either: the result stays in the data directory.
        from gonio.cli import scan_commands

        later = tmp_path / "linen.h5"
        checked = scan_commands.check_output_path

        def then_appears(out: Path, *args: Any, **kwargs: Any) -> None:
            checked(out, *args, **kwargs)
            later.write_bytes(b"the other scan's result")

        capsys.readouterr()
        with pytest.MonkeyPatch.context() as m:
            m.setattr(scan_commands, "check_output_path", then_appears)
            assert main([*argv, "--specimen", "linen", "-o", str(later)]) == 2
        err = capsys.readouterr().err
        assert later.read_bytes() == b"the other scan's result"
        kept = re.search(r"it is kept in (\S+\.h5): copy it from there", err)
        assert f"completed, but {later} appeared while it was measured" in err, err
        assert kept is not None and Path(kept.group(1)).is_file(), err
        assert "--overwrite" in err and not list(tmp_path.glob(".linen.h5*.part"))
    assert old.read_bytes()[:8] == b"\x89HDF\r\n\x1a\n"  # the HDF5 signature
