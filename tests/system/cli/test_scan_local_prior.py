"""A simulated scan of a measured material the default basis holds (issue 23 item 3): the fit
leans on that material's own shape, and the job's summary, the result file and the page's
metrics name it (docs/science.md 7.2.3)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from gonio.brdf.materials import measured
from gonio.brdf.reconstruction.localprior import EVIDENCE
from gonio.cli import main
from gonio.results import read_result
from gonio.store import JobStore

pytestmark = pytest.mark.system


def test_a_scan_of_a_folded_in_material_names_the_prior_it_leaned_on(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    # A matte felt: unlike the synthetic library's families, and one of the measured tables
    # folded into the default basis (not held out: this is the shipped basis a lab scans
    # with), so its own shape explains its readings best.
    felt = next(t for t in measured.measured_tables(()) if "acrylic_felt_green" in t.name)
    table = tmp_path / "felt.npz"
    felt.save(table)
    out = tmp_path / "felt.h5"
    data = tmp_path / "data"
    code = main(["scan", "--no-export-fits", "--sim", "--material", str(table), "--rotations", "8",
                 "--time-scale", "50", "--no-progress", "--specimen", "felt",
                 "--data-dir", str(data), "-o", str(out)])
    err = capsys.readouterr()
    assert code == 0, err.err
    assert f"prior: leaned on {felt.name} where no pair looks" in err.out
    res = read_result(out)
    assert res.metrics["local_prior"] == felt.name
    # At least the evidence the rule asks for: a Bayes factor of 20 after trying every
    # folded-in table (the shipped measured materials).
    tried = len(measured.measured_tables(()))
    assert res.metrics["local_prior_gain"] >= np.log(EVIDENCE * tried)
    assert res.provenance["local_prior"] == felt.name
    store = JobStore(data / "gonio.sqlite", durable=False)
    job = next(j for j in store.list_jobs() if j.specimen == "felt")
    assert job.summary is not None and job.summary["local_prior"] == felt.name
