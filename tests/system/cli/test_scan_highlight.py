"""A simulated scan whose highlight no pair reads (issue 23 item 4): the red paint of
docs/notes/2026-11-27-red-highlight.md, whose white highlight the default simulated rig's
pairs (none nearer than 7 degrees of th to the normal) bring back cyan at a fifth to a half of
its height. The result says so in the CLI's printout, the job's summary and the result file. And
the same rig's distance from the mirror direction, which the dry run and the result state."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from gonio.brdf.highlightread import EXCESS_LIMIT
from gonio.cli import main
from gonio.figures import headline_error
from gonio.results import read_result
from gonio.sim.rig import DEFAULT_LIGHTS, DEFAULT_SENSORS
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


def _least_half_vector_tilt_deg() -> float:
    """The default simulated rig's nearest pair to the mirror direction (it measures every
    light with every sensor): the half vector of unit vectors l and s is (l + s) / |l + s|,
    its tilt from the normal arccos of its z component."""
    def unit(theta: float, phi: float) -> np.ndarray:
        t, p = np.deg2rad(theta), np.deg2rad(phi)
        return np.array([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)])

    tilts = []
    for light in DEFAULT_LIGHTS:
        for sensor in DEFAULT_SENSORS:
            h = unit(*light) + unit(*sensor)
            tilts.append(np.rad2deg(np.arccos(h[2] / np.linalg.norm(h))))
    return float(min(tilts))


def test_a_scan_on_a_rig_without_a_pair_at_the_mirror_states_its_gap(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The default simulated rig's pairs stand 7 degrees or more off the mirror direction: the
    dry run says so before the scan, the result after it (issue 23 item 4)."""
    data = tmp_path / "data"
    common = ["--sim", "--material", "solid-red-paint", "--time-scale", "1000",
              "--no-progress", "--data-dir", str(data)]
    assert main(["scan", "--dry-run", *common]) == 0
    dry = capsys.readouterr().out
    gap = _least_half_vector_tilt_deg()
    assert f"note: no pair's half vector comes within {gap:.1f} degrees of the specimen" in dry
    out = tmp_path / "red.h5"
    code = main(["scan", "--no-export-fits", *common, "-o", str(out)])
    err = capsys.readouterr()
    assert code == 0, err.err
    # The red paint's highlight is not read either: that warning already says to read a pair
    # near the mirror direction, so the headline's meaning gives the gap alone.
    assert f"Note: no pair's half vector comes within {gap:.1f} degrees" in err.out
    res = read_result(out)
    # A fact of the layout: the headline's number is marked as it would be without it.
    without = {k: v for k, v in res.metrics.items() if not k.startswith("mirror_gap")}
    with_gap, plain = headline_error(dict(res.metrics)), headline_error(without)
    assert with_gap is not None and plain is not None
    assert with_gap["text"] == plain["text"]
    assert with_gap["meaning"].startswith(plain["meaning"])
    assert res.metrics["mirror_gap_deg"] == pytest.approx(gap, abs=1e-6)
    assert res.metrics["mirror_gap"] == res.provenance["mirror_gap"]
    assert f"within {gap:.1f} degrees" in str(res.metrics["mirror_gap"])
