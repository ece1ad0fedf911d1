"""``gonio scan`` with a built default basis that lacks the twofold symmetry: the dry run's
summary and the scan itself say so for a half-turn plan (once), not for a full turn."""

from __future__ import annotations

from pathlib import Path

import pytest

from gonio.cli import main
from tests.unit.test_arc_check import ODD, _cache_with, _says_what_and_what_to_do

pytestmark = pytest.mark.system


def _arc_lines(text: str) -> list[str]:
    """The warning lines about the arc, told by the arc warning's own words (the rig is also
    warned of as uncalibrated, and the 3-angle scan below with this small test basis
    reconstructs far above every reading and misses its readings: the physical bounds and
    basis misfit warnings of tests/system/cli/test_scan_bounds.py and test_scan_misfit.py)."""
    return [ln for ln in text.splitlines() if "warning" in ln and "over half a turn" in ln]


def test_the_dry_run_summary_warns_a_half_turn_plan(
        monkeypatch: pytest.MonkeyPatch, tmp_path: Path,
        capsys: pytest.CaptureFixture[str]) -> None:
    argv = ["scan", "--rig", "deploy/rig.example.toml", "--dry-run", "-o", "/dev/null"]
    _cache_with(monkeypatch, tmp_path, None)
    assert main(argv) == 0
    assert _arc_lines(capsys.readouterr().out) == []  # not built yet: nothing said, none built
    _cache_with(monkeypatch, tmp_path, ODD)
    assert main(argv) == 0
    (line,) = _arc_lines(capsys.readouterr().out)
    _says_what_and_what_to_do(line)
    assert main([*argv, "--span", "360"]) == 0
    assert _arc_lines(capsys.readouterr().out) == []


def test_a_half_turn_scan_says_it_once_and_runs(
        monkeypatch: pytest.MonkeyPatch, tmp_path: Path,
        capsys: pytest.CaptureFixture[str]) -> None:
    from gonio.sim.rig import SimRigOptions, start_sim_rig

    _cache_with(monkeypatch, tmp_path, ODD)
    rig = tmp_path / "rig" / "rig.toml"
    rig.parent.mkdir()
    with start_sim_rig(SimRigOptions(time_scale=10.0, settle_s=0.0, config_path=rig)):
        code = main(["scan", "--no-export-fits",
                     "--rig", str(rig), "--rotations", "3", "--no-progress",
                     "--data-dir", str(tmp_path / "data"), "-o", str(tmp_path / "a.h5")])
    err = capsys.readouterr().err
    lines = [ln for ln in _arc_lines(err) if ln.startswith("warning:")]
    assert len(lines) == 1, err
    _says_what_and_what_to_do(lines[0])
    assert code == 0 and (tmp_path / "a.h5").is_file()  # warned, not refused
