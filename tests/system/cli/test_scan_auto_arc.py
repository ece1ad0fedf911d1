"""``gonio scan --sim --arc auto``: the first round tests twofold symmetry on the simulated
rig's real sensors (Modbus, with their shot and read noise) and the scan takes the arc the
specimen needs: the default material (twofold symmetric) stays on half a turn, a tilted-facet
table from the library's asymmetric families (``--material FILE.npz``) goes to a full turn and
is reconstructed with the basis with odd harmonics. The choices are in the output, the job's
events, the result's metrics and provenance."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from gonio.brdf.materials import library
from gonio.brdf.models import analytic as bm
from gonio.brdf.reconstruction.basis import default_basis_path
from gonio.cli import main
from gonio.plans.arc import fill_angles, first_round_angles
from gonio.results import read_result
from gonio.store import JobStore
from tests.unit.brdf.reconstruction.test_reconstruct import random_basis
from tests.unit.brdf.reconstruction.test_reconstruct_joint import _with_prior

pytestmark = pytest.mark.system


def _scan(tmp_path: Path, capsys: pytest.CaptureFixture[str], *extra: str
          ) -> tuple[str, JobStore, dict]:
    out, data = tmp_path / "a.h5", tmp_path / "data"
    code = main(["scan", "--no-export-fits",
                 "--sim", "--arc", "auto", "--rotations", "8", "--time-scale", "50",
                 "--no-progress", "--specimen", "s", "--data-dir", str(data), "-o", str(out),
                 *extra])
    cap = capsys.readouterr()
    assert code == 0, cap.err
    store = JobStore(data / "gonio.sqlite")
    job = [j for j in store.list_jobs() if j.kind == "uniform"][-1]
    return cap.out + cap.err, store, {"job": job, "result": read_result(out)}


def _angles(store: JobStore, job_id: int) -> list[float]:
    return sorted(s.specimen_deg for s in store.steps(job_id))


def test_a_symmetric_specimen_stays_on_half_a_turn(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    text, store, got = _scan(tmp_path, capsys)
    job = got["job"]
    # The simulated rig's pairs lie in planes 30-144 deg apart: one opposite.
    assert _angles(store, job.id) == pytest.approx(sorted(first_round_angles(0.0, 8, 1)))
    (ev,) = [e for e in store.events_after(0, job_id=job.id) if e.type == "arc_test"]
    assert ev.data["symmetric"] and ev.data["arc_deg"] == 180.0 and ev.data["dof"] > 0
    assert "arc: the specimen reads twofold symmetric" in text
    assert "arc: 180 deg" in text
    metrics = got["result"].metrics
    assert metrics["arc_symmetric"] is True or metrics["arc_symmetric"] == 1
    assert metrics["arc_deg"] == 180.0
    assert metrics["arc_test_p_value"] == pytest.approx(ev.data["p_value"])
    assert json.loads(got["result"].provenance["arc_test"])["statistic"] == \
        pytest.approx(ev.data["statistic"])
    assert job.summary is not None and job.summary["arc_deg"] == 180.0


def test_a_tilted_facet_specimen_goes_to_a_full_turn(
        tmp_path: Path, capsys: pytest.CaptureFixture[str],
        monkeypatch: pytest.MonkeyPatch) -> None:
    spec = next(s for s in library.library_specs(asymmetric=True)
                if s.name == "tilted-facet-002")
    table = tmp_path / "tilted-facet.npz"
    bm.tabulate(spec.model, np.float32).save(table)
    # The basis for specimens without twofold symmetry, as a built install has it: a small one
    # with an odd harmonic (building the real one takes minutes) in a cache of this test's own.
    monkeypatch.setenv("GONIO_CACHE_DIR", str(tmp_path / "cache"))
    odd = _with_prior(random_basis(7, seed=2), {0: 1.0, 1: 0.3, 2: 0.5})
    asym_path = default_basis_path(asymmetric=True)
    asym_path.parent.mkdir(parents=True)
    odd.save(asym_path)
    text, store, got = _scan(tmp_path, capsys, "--material", str(table))
    job = got["job"]
    # The first round, then the opposites it had not read: 16 uniform angles over the turn.
    assert _angles(store, job.id) == pytest.approx([22.5 * k for k in range(16)])
    fill = sorted(s.specimen_deg for s in store.steps(job.id) if s.round == 1)
    assert fill == pytest.approx(fill_angles(0.0, 8, 1))
    (ev,) = [e for e in store.events_after(0, job_id=job.id) if e.type == "arc_test"]
    assert not ev.data["symmetric"] and ev.data["arc_deg"] == 360.0
    assert ev.data["p_value"] < 1e-6
    assert "NOT twofold symmetric" in text and "arc: 360 deg" in text
    metrics = got["result"].metrics
    assert metrics["arc_deg"] == 360.0 and not metrics["arc_symmetric"]
    assert metrics["n_angles"] == 16
    # Reconstructed with the basis with odd harmonics, and said so (issue 25).
    assert metrics["reconstruction_basis"] == "asymmetric" and metrics["K"] == odd.K
    assert got["result"].provenance["basis_switch"] == metrics["basis_switch"]
    assert "basis: the twofold symmetry test found the specimen NOT twofold symmetric" in text
    (switch,) = [e for e in store.events_after(0, job_id=job.id) if e.type == "basis_switch"]
    assert switch.data["basis"] == "asymmetric"


def test_the_asymmetric_basis_is_built_while_the_other_half_turn_is_read(
        tmp_path: Path, capsys: pytest.CaptureFixture[str],
        monkeypatch: pytest.MonkeyPatch) -> None:
    """On an install without the basis for asymmetric specimens, its build (minutes) began at
    finishing, after the last reading. It now begins when the test calls the specimen
    asymmetric, in a thread of its own, while the stage reads the fill round; finishing waits
    for what is left. The build here is a stand-in (the real one takes minutes) that saves a
    small basis with an odd harmonic where the real one would be cached."""
    import sqlite3
    import threading

    from gonio.brdf.reconstruction import basis as basis_module

    spec = next(s for s in library.library_specs(asymmetric=True)
                if s.name == "tilted-facet-002")
    table = tmp_path / "tilted-facet.npz"
    bm.tabulate(spec.model, np.float32).save(table)
    monkeypatch.setenv("GONIO_CACHE_DIR", str(tmp_path / "cache"))
    db = tmp_path / "data" / "gonio.sqlite"
    odd = _with_prior(random_basis(7, seed=2), {0: 1.0, 1: 0.3, 2: 0.5})
    real = basis_module.default_basis
    builds: list[tuple[str, int]] = []

    def default_basis(*args: object, asymmetric: bool = False, **kw: object) -> object:
        if not asymmetric:
            return real(*args, **kw)  # type: ignore[arg-type]
        # Where the scan was when the build began: its readings stored so far.
        with sqlite3.connect(db) as con:
            (n,) = con.execute("SELECT COUNT(*) FROM readings").fetchone()
        builds.append((threading.current_thread().name, int(n)))
        path = basis_module.default_basis_path(asymmetric=True)
        path.parent.mkdir(parents=True, exist_ok=True)
        odd.save(path)
        return odd

    monkeypatch.setattr(basis_module, "default_basis", default_basis)
    text, store, got = _scan(tmp_path, capsys, "--material", str(table))
    job = got["job"]
    readings = store.readings(job.id)
    # Built once, in the prewarm's thread (not finishing's), after the first round's readings
    # (8 of the 16 angles) were in.
    assert len(builds) == 1, builds
    thread, stored = builds[0]
    assert thread == "gonio-asymmetric-basis"
    assert stored >= len(readings) // 2, (stored, len(readings))
    events = list(store.events_after(0, job_id=job.id))
    (test_ev,) = [e for e in events if e.type == "arc_test"]
    (prewarm,) = [e for e in events if e.type == "basis_prewarm"]
    assert prewarm.data["basis"] == "asymmetric" and prewarm.seq > test_ev.seq
    assert "while the other half turn is read" in prewarm.data["message"]
    assert "built for this job while the stage read its other half turn" in text
    # Started before the fill round's first reading was taken, not at finishing.
    fill = {s.angle_index for s in store.steps(job.id) if s.round == 1}
    assert fill and prewarm.time < min(r.t_read for r in readings if r.angle_index in fill)
    # And finishing reconstructs with it, as before.
    assert got["result"].metrics["reconstruction_basis"] == "asymmetric"
    assert got["result"].metrics["K"] == odd.K
