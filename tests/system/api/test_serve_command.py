"""`gonio serve` user errors: each gets one clear line and exit code 2."""

from __future__ import annotations

import io
import os
import re
import sys
from pathlib import Path

import pytest

from gonio.cli import main
from gonio.results import read_result


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["serve", "--port", "0"], "no rig config: give --rig"),
        (["serve", "--demo-scan"], "need --sim"),
        (["serve", "--sim", "--port", "70000"], "--port 70000"),
        (["serve", "--rig", "missing-rig.toml", "--port", "0"], "no such rig config file"),
        (["serve", "--sim", "--time-scale", "0", "--port", "0"],
         "--time-scale: expected a finite number > 0, got 0"),
        (["serve", "--sim", "--time-scale", "inf", "--port", "0"],
         "--time-scale: expected a finite number > 0, got inf"),
        (["serve", "--throwaway", "--port", "0"], "need --sim"),
        (["serve", "--sim", "--throwaway", "--data-dir", "d", "--port", "0"],
         "--throwaway and --data-dir exclude each other"),
    ],
)
def test_serve_user_errors(argv: list[str], message: str, capsys: pytest.CaptureFixture[str],
                           tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("GONIO_API_KEYS", raising=False)
    try:
        code = main(argv)
    except SystemExit as exc:  # flags of the wrong type are refused by argparse itself
        code = exc.code
    assert code == 2
    err = capsys.readouterr().err
    assert "gonio serve: error:" in err and message in err


def test_serve_reports_bad_daemon_config(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    cfg = tmp_path / "daemon.toml"
    cfg.write_text("[server]\nprot = 1\n")
    assert main(["serve", "--config", str(cfg), "--sim"]) == 2
    assert "unknown key 'server.prot'" in capsys.readouterr().err


@pytest.mark.timeout(400)
def test_sim_demo_scan_keeps_its_data_and_prints_the_result_file(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """Default data directory: the user data folder's serve-sim/ (the session's temporary
    GONIO_DATA_DIR here); the demo prints a result file that is still there after exit."""
    monkeypatch.delenv("GONIO_API_KEYS", raising=False)
    assert main(["serve", "--sim", "--demo-scan", "--no-export-fits", "--port", "0",
                 "--time-scale", "10"]) == 0
    out = capsys.readouterr().out
    data = Path(os.environ["GONIO_DATA_DIR"]) / "serve-sim"
    assert f"data directory {data} (kept across restarts)" in out
    m = re.search(r"demo scan result file: (\S+)", out)
    assert m is not None, out
    result = Path(m.group(1))
    assert result.parent == data / "results" and result.is_file()
    demo = read_result(result)  # --no-export-fits: reconstructed, fits left to the exports
    assert demo.table is not None and demo.factored is None and demo.principled is None
    assert "api/v1/jobs" not in out.split("demo scan completed")[1]  # no dead URL
    # The simulated rig's layout has no pair at the mirror direction: the summary says what
    # that hides, with the gap the result records.
    gap = float(demo.metrics["mirror_gap_deg"])
    assert gap > 1.0
    assert f"  Note: no pair's half vector comes within {gap:.1f} degrees of the" in \
        out.split("demo scan completed")[1]
    # Progress names the specimen's angle (0-360), not the multi-turn stage position.
    angles = [float(a) for a in re.findall(r"specimen at (\S+) deg", out)]
    assert len(angles) == 8 and all(0 <= a < 360 for a in angles), out
    # Run again on the same folder: the calibration is still in effect, none is queued.
    assert main(["serve", "--sim", "--demo-scan", "--no-export-fits", "--port", "0",
                 "--time-scale", "10"]) == 0
    again = capsys.readouterr().out
    assert "calibration: in effect" in again and "calibrating the simulated rig" not in again


class _Terminal(io.StringIO):
    """One stream for standard output and error, as a terminal is, that keeps each write."""

    def __init__(self) -> None:
        super().__init__()
        self.writes: list[str] = []

    def write(self, text: str) -> int:
        self.writes.append(text)
        return super().write(text)


@pytest.mark.timeout(400)
def test_sim_demo_scan_writes_each_line_whole(monkeypatch: pytest.MonkeyPatch) -> None:
    # The demo's progress lines are printed from its own thread while the daemon logs from
    # others to the same terminal. print() wrote "  job 2: completed" and its newline
    # separately: on an unbuffered stream the daemon's next log line landed between them, on
    # the same line. Each line is now one write with its newline.
    monkeypatch.delenv("GONIO_API_KEYS", raising=False)
    term = _Terminal()
    monkeypatch.setattr(sys, "stdout", term)
    monkeypatch.setattr(sys, "stderr", term)
    assert main(["serve", "--sim", "--throwaway", "--demo-scan", "--no-export-fits",
                 "--port", "0", "--time-scale", "10"]) == 0
    said = [w for w in term.writes if w]
    assert any(re.fullmatch(r"  job \d+: completed\n", w) for w in said), said
    assert any(w.startswith("demo scan result file: ") for w in said), said
    broken = [w for w in said if not w.endswith("\n")]
    assert not broken, broken


def test_an_interrupted_scan_keeps_its_simulated_material_across_restarts(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from gonio.cli.serve_command import _sim_material
    from gonio.jobstates import JobState
    from gonio.store import JobStore

    data = tmp_path / "data"
    assert _sim_material(data, "felt-001") == "felt-001"  # first start: as asked, recorded
    store = JobStore(data / "gonio.sqlite")
    job = store.create_job(kind="uniform", specimen="felt", plan={"kind": "uniform"}, rig={})
    store.set_state(job.id, JobState.RUNNING)
    store.close()
    # Restarted with another material while the job is unfinished: the job's stays.
    assert _sim_material(data, "paint-002") == "felt-001"
    err = capsys.readouterr().err
    assert f"job {job.id} was interrupted while measuring material 'felt-001'" in err
    # Not "until the job ends": the material is the whole start's.
    assert "every scan until this daemon stops measures it too" in err, err
    assert f"--material 'paint-002' applies at the next start once job {job.id} has ended" \
        in err, err
    store = JobStore(data / "gonio.sqlite")
    store.set_state(job.id, JobState.ABORTED, reason="test")
    store.close()
    assert _sim_material(data, "paint-002") == "paint-002"  # nothing to resume: as asked
    # A job interrupted while reconstructing (every angle measured, its truth kept when its
    # finishing began) holds no specimen: the session measured the old material for hours.
    assert _sim_material(data, "felt-001") == "felt-001"
    store = JobStore(data / "gonio.sqlite")
    done = store.create_job(kind="uniform", specimen="felt", plan={"kind": "uniform"}, rig={})
    store.set_state(done.id, JobState.RUNNING)
    store.set_state(done.id, JobState.RECONSTRUCTING)
    store.set_finishing_inputs(done.id, {"true_material": {"name": "felt-001"}})
    store.close()
    capsys.readouterr()
    assert _sim_material(data, "paint-002") == "paint-002"
    assert "was interrupted" not in capsys.readouterr().err
