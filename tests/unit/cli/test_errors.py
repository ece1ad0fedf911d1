"""Bad input on the command line ends in one clear line on stderr and a non-zero exit code,
never a traceback: flags out of range, files of the wrong type, paths that cannot be written."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from gonio.brdf.reconstruction.samples import Samples
from gonio.cli import main
from tests.unit.brdf.reconstruction.test_basis import small_basis


def _one_error_line(err: str) -> str:
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert "Traceback" not in err
    assert lines, "no message at all"
    assert "error:" in lines[-1]
    return lines[-1]


@pytest.mark.parametrize(
    ("flag", "value", "words"),
    [
        ("--time-scale", "inf", "--time-scale: expected a finite number > 0, got inf"),
        ("--time-scale", "nan", "--time-scale: expected a finite number > 0"),
        ("--threshold", "0", "--threshold: expected a finite number > 0, got 0"),
        ("--averages", "0", "--averages: expected a whole number >= 1, got 0"),
        ("--averages", "1.5", "--averages: expected a whole number >= 1, got '1.5'"),
        ("--exposure", "-1", "--exposure: expected a finite number > 0"),
        ("--start-deg", "1e999", "--start-deg: expected a finite number"),
    ],
)
def test_scan_flags_out_of_range(
    flag: str, value: str, words: str, capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(SystemExit) as exc:
        main(["scan", "--sim", "--adaptive", flag, value, "-o", "unused.h5"])
    assert exc.value.code == 2
    assert words in capsys.readouterr().err


def test_start_angle_outside_a_turn_is_refused_not_wrapped(
    capsys: pytest.CaptureFixture[str]
) -> None:
    # -500 deg is the same specimen angle as 220 deg (-500 + 2 x 360); say so instead of
    # measuring 220 without a word.
    assert main(["scan", "--rig", "deploy/rig.example.toml", "--start-deg", "-500",
                 "-o", "unused.h5"]) == 2
    line = _one_error_line(capsys.readouterr().err)
    assert "start_deg" in line and "[0, 360)" in line and "220" in line
    # pydantic's "Value error, " prefix is not part of what the user reads.
    assert "Value error" not in line, line


@pytest.fixture()
def samples_and_basis(tmp_path: Path) -> tuple[Path, Path]:
    basis = small_basis().save(tmp_path / "basis.npz")
    samples = tmp_path / "s.npz"
    Samples(np.deg2rad([[10.0, 20.0, 30.0]]), np.zeros(1), np.zeros(1), np.ones((1, 1, 3)),
            ("R", "G", "B")).save(samples)
    return samples, basis


def test_reconstruct_into_a_missing_directory(
    samples_and_basis: tuple[Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    samples, basis = samples_and_basis
    target = tmp_path / "nonexistent" / "dir" / "x.npz"
    assert main(["reconstruct", str(samples), "--basis", str(basis), "-k", "3",
                 "-o", str(target)]) == 1
    line = _one_error_line(capsys.readouterr().err)
    assert "No such file or directory" in line and "check that the directory exists" in line
    assert "nonexistent" in line


@pytest.mark.parametrize(
    ("content", "words"),
    [
        (b"\x89HDF\r\n\x1a\n" + bytes(64), "HDF5 file"),
        (bytes(range(256)) * 4, "starts with the bytes"),
        (b"", "empty"),
        (b"\x93NUMPY\x01\x00" + bytes(64), "single .npy array"),
    ],
    ids=["hdf5", "random-bytes", "empty", "npy"],
)
def test_wrong_file_type_as_npz_never_suggests_allow_pickle(
    content: bytes, words: str, samples_and_basis: tuple[Path, Path], tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    _, basis = samples_and_basis
    bad = tmp_path / "scan.npz"
    bad.write_bytes(content)
    assert main(["reconstruct", str(bad), "--basis", str(basis), "-o",
                 str(tmp_path / "o.npz")]) == 2
    line = _one_error_line(capsys.readouterr().err)
    assert words in line and str(bad) in line
    assert "pickle" not in line


def test_binary_rig_config_names_the_file(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    rig = tmp_path / "rig.toml"
    rig.write_bytes(bytes(range(128, 256)) * 3)
    assert main(["scan", "--rig", str(rig), "-o", str(tmp_path / "x.h5")]) == 2
    line = _one_error_line(capsys.readouterr().err)
    assert str(rig) in line and "not a text file" in line


def test_data_dir_that_cannot_be_created(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # A file where a directory should be: the portable stand-in for an unwritable location
    # (the tests may run as root, who may write anywhere).
    blocker = tmp_path / "data"
    blocker.write_text("not a directory")
    assert main(["serve", "--sim", "--port", "0", "--data-dir", str(blocker / "sub")]) == 1
    line = _one_error_line(capsys.readouterr().err)
    assert str(blocker / "sub") in line and "Not a directory" in line


def test_jobs_show_into_a_closed_pipe(tmp_path: Path) -> None:
    from gonio.store import JobStore

    db = tmp_path / "jobs.sqlite"
    store = JobStore(db)
    store.create_job(kind="uniform", specimen="x" * 50, plan={"kind": "uniform"},
                     rig={"pairs": [{"light": "L1", "sensor": f"S{i}"} for i in range(3000)]})
    store.close()
    proc = subprocess.Popen(
        [sys.executable, "-c", "from gonio.cli import main; raise SystemExit(main())",
         "jobs", "show", "1", "--db", str(db)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, env={**os.environ},
    )
    assert proc.stdout is not None and proc.stderr is not None
    proc.stdout.close()  # like `| head` that has already exited: every write fails with EPIPE
    err = proc.stderr.read().decode()
    assert proc.wait(timeout=120) != 0
    assert "Traceback" not in err and "BrokenPipe" not in err


def test_a_value_the_plan_model_refuses_is_one_line_naming_the_field(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    # pydantic's error reaches main (which catches it only once a command has loaded pydantic):
    # the plan allows at most 60 s of light settling (ExposureSettings.light_settle_s).
    code = main(["scan", "--sim", "-o", str(tmp_path / "r.h5"), "--light-settle", "61"])
    assert code == 2
    line = _one_error_line(capsys.readouterr().err)
    assert line.startswith("gonio scan: error: light_settle_s:") and "60" in line
    assert not (tmp_path / "r.h5").exists()
