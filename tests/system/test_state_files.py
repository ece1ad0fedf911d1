"""No state file trusted blindly: the calibration, the job store and result files of a data
directory, as real daemons and CLI commands in child processes meet them.

The data directory under test is made the way a lab makes one: ``gonio serve --sim`` calibrates
its simulated rig at start-up (job 1, a white reference) and measures one scan (job 2); then
each test damages a copy of it as a crash, an editor or a restored backup would, and starts a
daemon or a command on it. ``serve --rig`` daemons drive a simulated rig run in this process
with the real drivers (as tests/system/test_durable_state.py does).
"""

from __future__ import annotations

import hashlib
import json
import shutil
import sqlite3
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import h5py
import numpy as np
import pytest

from gonio.results import read_result
from gonio.sim.rig import SimRig, SimRigOptions, start_sim_rig
from tests.system.daemon_proc import gonio, start_daemon, wait_for

# The module's first scan may build the default reconstruction basis (minutes on a fresh
# session, more when the cores are saturated), as in tests/system/cli/test_scan.py.
pytestmark = [pytest.mark.system, pytest.mark.timeout(1500)]

ROTATIONS = 4
N_PAIRS = 12
"""The simulated rig's pairs: 3 lights x 4 sensors, every light with every sensor."""
FAST = {"exposure_s": 0.01, "light_settle_s": 0.0}
SCAN = {"kind": "uniform", "specimen": "felt", "rotations": ROTATIONS}
TERMINAL = ("completed", "failed", "aborted", "halted")


def _wait_final(c: Any, job: int, timeout: float = 1200) -> dict[str, Any]:
    row: dict[str, Any] = {}

    def done() -> bool:
        row.update(c.get(f"/api/v1/jobs/{job}").json())
        return row["state"] in TERMINAL

    wait_for(done, timeout, f"job {job} to finish")
    return row


@pytest.fixture(scope="module")
def served(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A ``gonio serve --sim`` data directory after its start-up calibration (job 1) and one
    calibrated scan (job 2); the daemon stopped."""
    data = tmp_path_factory.mktemp("served") / "data"
    d = start_daemon(["--no-export-fits",
                      "--sim", "--port", "0", "--time-scale", "10", "--data-dir", str(data)])
    try:
        wait_for(lambda: "calibration job 1 completed" in d.text(), 300,
                 "the start-up calibration")
        with d.client() as c:
            r = c.post("/api/v1/jobs", json={"plan": SCAN})
            assert r.status_code == 201, r.text
            row = _wait_final(c, r.json()["id"])
            assert row["state"] == "completed", row
            assert row["result"]["calibrated"] is True
    finally:
        d.stop()
    # One file: the last connection's checkpoint folded the WAL into the store.
    with sqlite3.connect(data / "gonio.sqlite") as con:
        con.execute("PRAGMA wal_checkpoint(TRUNCATE)")
    return data


@pytest.fixture
def data(served: Path, tmp_path: Path) -> Path:
    """A copy of :func:`served`'s data directory for one test to damage."""
    return Path(shutil.copytree(served, tmp_path / "data"))


@pytest.fixture(scope="module")
def rig(tmp_path_factory: pytest.TempPathFactory) -> Iterator[SimRig]:
    """A simulated rig (this process) for ``serve --rig`` daemons and ``gonio scan --rig``."""
    path = tmp_path_factory.mktemp("rig") / "rig.toml"
    with start_sim_rig(SimRigOptions(time_scale=10.0, settle_s=0.0, config_path=path)) as s:
        yield s


def _refused(args: list[str]) -> str:
    """Start ``gonio serve ARGS``, expecting it to refuse; its output."""
    try:
        d = start_daemon(args)
    except RuntimeError as exc:
        return str(exc)
    d.stop()
    pytest.fail(f"gonio serve {' '.join(args)} started:\n{d.text()}")


def _edit_factors(path: Path, change: Callable[[float], float]) -> None:
    cal = json.loads(path.read_text())
    for p in cal["pairs"]:
        p["factor"] = [change(v) for v in p["factor"]]
    path.write_text(json.dumps(cal))  # NaN is written as JSON's common NaN extension


def _sha(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


# --------------------------------------------------------------------------- item 1
# One factor that is not finite and positive (zero and NaN meet the same check of the file:
# tests/unit/test_calibration.py), and one that no reading of this rig's sensors could give.
@pytest.mark.parametrize(("change", "words"), [
    (lambda v: -v, "finite and positive"),
    # A reference that read a billion times its full scale: no calibration of this rig.
    (lambda v: v * 1e-9, "outside what sensor"),
], ids=["negated", "implausible"])
def test_serve_sim_refuses_a_nonsense_calibration(
    data: Path, change: Callable[[float], float], words: str
) -> None:
    cal = data / "calibration.json"
    _edit_factors(cal, change)
    before = _sha(cal)
    text = _refused(["--sim", "--port", "0", "--time-scale", "10", "--data-dir", str(data)])
    assert f"calibration file {cal}" in text and words in text, text
    assert "run a calibration job again" in text.lower(), text
    assert "Traceback" not in text, text
    assert _sha(cal) == before  # left as it was, for inspection


def test_a_calibration_without_some_pairs_refuses_their_scan_before_it_moves(
    data: Path, rig: SimRig
) -> None:
    cal = json.loads((data / "calibration.json").read_text())
    gone = {("L2", "S1"), ("L3", "S4")}
    cal["pairs"] = [p for p in cal["pairs"] if (p["light"], p["sensor"]) not in gone]
    assert len(cal["pairs"]) == N_PAIRS - len(gone)
    (data / "calibration.json").write_text(json.dumps(cal))
    rig.load("specimen")
    d = start_daemon(["--no-export-fits",
                      "--rig", str(rig.config_path), "--data-dir", str(data), "--port", "0"])
    try:
        with d.client() as c:
            position = rig.motion.position_deg()
            r = c.post("/api/v1/jobs", json={"plan": SCAN})
            assert r.status_code == 422, r.text
            detail = r.json()["detail"]
            assert "L2/S1" in detail and "L3/S4" in detail and "calibration job" in detail
            assert [j["id"] for j in c.get("/api/v1/jobs").json()] == [1, 2]  # nothing stored
            assert rig.motion.position_deg() == position
            # The pairs it does calibrate may be measured: every value of that result is 1/sr.
            kept = [{"light": p["light"], "sensor": p["sensor"]} for p in cal["pairs"]]
            r = c.post("/api/v1/jobs", json={"plan": {**SCAN, "pairs": kept}})
            assert r.status_code == 201, r.text
            row = _wait_final(c, r.json()["id"])
            assert row["state"] == "completed", row
            assert row["result"]["calibrated"] is True
            assert row["result"]["pairs"] == len(kept)
    finally:
        d.stop()


def test_gonio_scan_refuses_bad_calibration_files(data: Path, rig: SimRig, tmp_path: Path
                                                 ) -> None:
    """``--calibration FILE`` and the data directory's own file, damaged or partial: refused
    before anything moves, naming the file (or the pairs)."""
    out = tmp_path / "out.h5"
    base = ["scan", "--rig", str(rig.config_path), "--rotations", "3", "--no-progress",
            "-o", str(out)]
    negated = tmp_path / "negated.json"
    shutil.copyfile(data / "calibration.json", negated)
    _edit_factors(negated, lambda v: -v)
    partial = tmp_path / "partial.json"
    cal = json.loads((data / "calibration.json").read_text())
    cal["pairs"] = cal["pairs"][1:]
    partial.write_text(json.dumps(cal))
    first = json.loads((data / "calibration.json").read_text())["pairs"][0]
    missing = f"{first['light']}/{first['sensor']}"
    torn = tmp_path / "torn"
    torn.mkdir()
    text = (data / "calibration.json").read_text()
    (torn / "calibration.json").write_text(text[: len(text) // 2])
    position = rig.motion.position_deg()
    for extra, words in (
        (["--calibration", str(negated), "--data-dir", str(tmp_path / "d1")],
         [f"--calibration {negated}: not a calibration file", "finite and positive"]),
        (["--calibration", str(partial), "--data-dir", str(tmp_path / "d2")],
         [f"no factors for 1 of the {N_PAIRS} pairs", missing]),
        (["--data-dir", str(torn)],
         [f"calibration file {torn / 'calibration.json'}", "damaged"]),
    ):
        r = gonio([*base, *extra])
        assert r.returncode == 2, r.stdout + r.stderr
        assert all(w in r.stderr for w in words), r.stderr
        assert "Traceback" not in r.stderr
    assert not out.exists()
    assert rig.motion.position_deg() == position


# --------------------------------------------------------------------------- item 2
def _calibrate(rig: SimRig, c: Any, specimen: str) -> int:
    rig.place_white_reference()
    plan = {"kind": "calibration", "reference_albedo": 0.99, "specimen": specimen,
            "rotations": 2, "exposure": FAST}
    r = c.post("/api/v1/jobs", json={"plan": plan})
    assert r.status_code == 201, r.text
    row = _wait_final(c, r.json()["id"])
    assert row["state"] == "completed", row
    return int(row["id"])


def _served_specimen(c: Any, job: int, tmp_path: Path) -> str:
    """The specimen recorded in the result file the daemon sends for ``job``."""
    r = c.get(f"/api/v1/jobs/{job}/result")
    assert r.status_code == 200, r.text
    got = tmp_path / f"got-{job}.h5"
    got.write_bytes(r.content)
    with h5py.File(got, "r") as f:
        return str(f.attrs["specimen"])


def test_each_data_directory_serves_its_own_results_wherever_the_daemon_starts(
    rig: SimRig, tmp_path: Path
) -> None:
    labs = {"lab-a": "A-felt", "lab-b": "B-velvet"}
    for lab, specimen in labs.items():
        (tmp_path / lab).mkdir()
        # Each lab's daemon started in its own folder, on ./data.
        d = start_daemon(["--no-export-fits",
                          "--rig", str(rig.config_path), "--data-dir", "data", "--port", "0"],
                         cwd=tmp_path / lab)
        try:
            with d.client() as c:
                assert _calibrate(rig, c, specimen) == 1
        finally:
            d.stop()
    third = tmp_path / "elsewhere"
    third.mkdir()
    restored = Path(shutil.copytree(tmp_path / "lab-a" / "data", tmp_path / "backup" / "data"))
    for cwd, data_dir in ((tmp_path / "lab-b", "../lab-a/data"),
                          (third, str(tmp_path / "lab-a" / "data")),
                          (third, str(restored))):
        d = start_daemon(["--no-export-fits",
                          "--rig", str(rig.config_path), "--data-dir", data_dir, "--port", "0"],
                         cwd=cwd)
        try:
            with d.client() as c:
                assert c.get("/api/v1/jobs/1").json()["specimen"] == "A-felt"
                assert _served_specimen(c, 1, tmp_path) == "A-felt", (cwd, data_dir)
        finally:
            d.stop()


def test_an_older_store_with_absolute_and_cwd_relative_paths_is_migrated_on_open(
    rig: SimRig, tmp_path: Path
) -> None:
    data = tmp_path / "moved" / "data"
    d = start_daemon(["--no-export-fits",
                      "--rig", str(rig.config_path), "--data-dir", str(data), "--port", "0"])
    try:
        with d.client() as c:
            assert [_calibrate(rig, c, s) for s in ("first", "second")] == [1, 2]
    finally:
        d.stop()
    # As an older gonio stored them: absolute (where the directory was before it moved), and
    # relative to the working directory it was started in; and without the mark that a gonio
    # which makes them relative leaves in the store.
    old = {1: "/srv/old-lab/data/results/job-1.h5", 2: "data/results/job-2.h5"}
    with sqlite3.connect(data / "gonio.sqlite") as con:
        con.execute("DELETE FROM meta WHERE key = 'result_paths'")
        for job, path in old.items():
            summary = json.loads(con.execute("SELECT summary FROM jobs WHERE id = ?",
                                             (job,)).fetchone()[0])
            summary.update(result_path=path, calibration_path="/srv/old-lab/data/"
                           "calibration.json")
            con.execute("UPDATE jobs SET result_path = ?, summary = ? WHERE id = ?",
                        (path, json.dumps(summary), job))
    d = start_daemon(["--no-export-fits",
                      "--rig", str(rig.config_path), "--data-dir", str(data), "--port", "0"])
    try:
        with d.client() as c:
            assert _served_specimen(c, 1, tmp_path) == "first"
            assert _served_specimen(c, 2, tmp_path) == "second"
    finally:
        d.stop()
    with sqlite3.connect(data / "gonio.sqlite") as con:
        rows = con.execute("SELECT id, result_path, summary FROM jobs ORDER BY id").fetchall()
    for job, path, summary in rows:
        assert path == f"results/job-{job}.h5"
        assert json.loads(summary)["result_path"] == path
        assert json.loads(summary)["calibration_path"] == "calibration.json"


# --------------------------------------------------------------------------- item 7
def test_a_torn_calibration_file_is_refused_by_name_under_serve_rig(data: Path, rig: SimRig
                                                                   ) -> None:
    cal = data / "calibration.json"
    cal.write_text(cal.read_text()[:3])  # '{\n ' : what a crash mid-write leaves
    text = _refused(["--rig", str(rig.config_path), "--data-dir", str(data), "--port", "0"])
    assert f"calibration file {cal} is damaged" in text, text
    assert "restore it from a backup" in text and "Traceback" not in text, text


def _damage_middle_page(db: Path) -> None:
    with sqlite3.connect(db) as con:
        page = int(con.execute("PRAGMA page_size").fetchone()[0])
    pages = db.stat().st_size // page
    with open(db, "r+b") as f:
        f.seek(pages // 2 * page)
        f.write(b"\xa5" * page)


def test_a_damaged_job_store_is_refused_by_name_everywhere(data: Path, rig: SimRig) -> None:
    db = data / "gonio.sqlite"
    _damage_middle_page(db)
    before = _sha(db)
    for args in (["--rig", str(rig.config_path)], ["--sim", "--time-scale", "10"]):
        text = _refused([*args, "--data-dir", str(data), "--port", "0"])
        assert f"job store {db} is damaged" in text, text
        assert "restore it from a backup" in text and "Traceback" not in text, text
    r = gonio(["jobs", "list", "--db", str(db)])
    assert r.returncode != 0 and f"job store {db} is damaged" in r.stderr, r.stderr
    assert _sha(db) == before  # nothing was written to it


def test_a_truncated_result_is_refused_and_rebuilt_from_the_stored_readings(
    data: Path, tmp_path: Path
) -> None:
    result = data / "results" / "job-2.h5"
    original = Path(shutil.copyfile(result, tmp_path / "original.h5"))
    with open(result, "r+b") as f:
        f.truncate(result.stat().st_size // 2)
    d = start_daemon(["--no-export-fits",
                      "--sim", "--port", "0", "--time-scale", "10", "--data-dir", str(data)])
    try:
        assert "job 2:" in d.text() and "gonio jobs rebuild 2" in d.text(), d.text()
        with d.client() as c:
            for what in ("result", "preview.png"):
                r = c.get(f"/api/v1/jobs/2/{what}")
                assert r.status_code == 500, (what, r.status_code)
                detail = r.json()["detail"]
                assert "job 2's result file is damaged" in detail, detail
                assert f"gonio jobs rebuild 2 --db {data / 'gonio.sqlite'}" in detail, detail
            # Rebuilt beside the running daemon, which then serves the new file.
            r = gonio(["jobs", "rebuild", "2", "--db", str(data / "gonio.sqlite")], timeout=1200)
            assert r.returncode == 0, r.stdout + r.stderr
            assert f"wrote {result}" in r.stdout and f"{N_PAIRS * ROTATIONS} stored" in r.stdout
            assert c.get("/api/v1/jobs/2/result").status_code == 200
            assert c.get("/api/v1/jobs/2/preview.png").status_code == 200
            assert c.get("/api/v1/jobs/2/metrics").json()["calibrated"] is True
    finally:
        d.stop()
    # The same readings and the same calibration: the same samples and reconstruction.
    new, old = read_result(result), read_result(original)
    np.testing.assert_array_equal(new.samples.values, old.samples.values)
    assert new.table is not None and old.table is not None
    np.testing.assert_allclose(new.table.values, old.table.values, rtol=1e-4, equal_nan=True)

    # Without the readings of one stage angle there is nothing faithful to rebuild from.
    with sqlite3.connect(data / "gonio.sqlite") as con:
        con.execute("DELETE FROM readings WHERE job_id = 2 AND angle_index = "
                    "(SELECT MIN(angle_index) FROM readings WHERE job_id = 2)")
    before = _sha(result)
    r = gonio(["jobs", "rebuild", "2", "--db", str(data / "gonio.sqlite")])
    assert r.returncode == 2, r.stdout + r.stderr
    expected = (f"holds {N_PAIRS * (ROTATIONS - 1)} of the {N_PAIRS * ROTATIONS} readings")
    assert "cannot rebuild job 2" in r.stderr and expected in r.stderr, r.stderr
    assert _sha(result) == before
