"""A simulated scan whose highlight no pair reads (issue 23 item 4): the red paint of
docs/notes/2026-11-27-red-highlight.md, whose white highlight the default simulated rig's
pairs (none nearer than 7 degrees of th to the normal) bring back cyan at a fifth to a half of
its height. The result says so in the CLI's printout, the job's summary and the result file."""

from __future__ import annotations

from pathlib import Path

import pytest

from gonio.brdf.highlightread import EXCESS_LIMIT
from gonio.cli import main
from gonio.results import read_result
from gonio.store import JobStore

pytestmark = pytest.mark.system


def test_a_scan_whose_highlight_no_pair_reads_says_so(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "red.h5"
    data = tmp_path / "data"
    code = main(["scan", "--no-export-fits", "--sim", "--material", "solid-red-paint",
                 "--time-scale", "1000", "--no-progress", "--specimen", "red",
                 "--data-dir", str(data), "-o", str(out)])
    err = capsys.readouterr()
    assert code == 0, err.err
    text = err.out + err.err
    assert "warning: the highlight is not read" in text
    assert "(HIGHLIGHT NOT READ)" in text  # the headline line, not only a warning line
    res = read_result(out)
    # Measured 4.48: the coat's lobe peaks between the pairs, the nearest 7 degrees away.
    assert res.metrics["highlight_excess"] > EXCESS_LIMIT
    assert res.metrics["highlight_peak_th_deg"] == 0.0
    assert res.metrics["highlight_nearest_deg"] > 5.0
    assert "prior's extrapolation" in str(res.metrics["highlight_not_read"])
    assert res.provenance["highlight_not_read"] == res.metrics["highlight_not_read"]
    store = JobStore(data / "gonio.sqlite", durable=False)
    job = store.get_job(2)  # job 1 is the simulated rig's white-reference calibration
    assert job.state.value == "completed" and job.summary is not None
    assert "not read" in job.summary["highlight_not_read"]
