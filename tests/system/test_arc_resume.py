"""An auto-arc scan that switches to a full turn keeps every reading exactly once across a
``kill -9`` and resumes on the arc it chose.

The child (``_scan_child.py``, arc auto) scans a tilted-facet specimen (no twofold symmetry)
on the simulated rig: 9 angles of its first round (8 over half a turn and 180: the rig's pairs
lie in planes spread around the normal, so one opposite tests it), the test, then 7 fill
angles. It is killed right after the first round's last checkpoint (before the test ran) or
three angles into the fill round (after the choice was stored), restarted, and compared with
an uninterrupted run of the same seed. An adaptive auto-arc plan (4 first angles and 0/180, the
test, 3 fill angles, then the posterior rule over the full turn up to 12 angles) is killed two
angles into its refinement round: resumed, it finishes that round on the full turn, every
reading once, and its rule still plans with the basis for specimens without twofold symmetry
(the one finishing reconstructs with; restored from the stored test, issue 25).
"""

from __future__ import annotations

import subprocess
from pathlib import Path

import pytest

from gonio.jobstates import JobState
from gonio.plans.arc import ARC_TEST_EVENT, fill_angles, first_round_angles
from gonio.store import JobStore
from tests.system._scan_child import kill_when_frozen, start_child

pytestmark = pytest.mark.system


def _child(db: Path, seed: int, freeze_after: int = 0, kind: str = "uniform"
           ) -> subprocess.Popen[str]:
    return start_child(db, seed, freeze_after, material="tilted-facet-002", arc="auto",
                       rotations=4 if kind == "adaptive" else 8, kind=kind)


@pytest.mark.parametrize("freeze_after", [9, 12], ids=["before-the-test", "in-the-fill"])
def test_sigkill_around_the_arc_switch_keeps_every_reading_once(
        tmp_path: Path, freeze_after: int) -> None:
    killed, clean = tmp_path / "killed.sqlite", tmp_path / "clean.sqlite"
    proc = _child(killed, 3, freeze_after)
    kill_when_frozen(proc)
    store = JobStore(killed)
    assert store.get_job(1).done_angles == freeze_after
    assert store.get_job(1).state is JobState.RUNNING
    tested = store.last_event(1, ARC_TEST_EVENT)
    # Killed inside the commit's event listener: the 9th angle's test had not run yet; three
    # angles into the fill, the choice was stored.
    assert (tested is None) == (freeze_after == 9)
    assert _child(killed, 3).communicate(timeout=300)[0].strip() == "running"
    assert _child(clean, 3).communicate(timeout=300)[0].strip() == "running"
    a_store, b_store = JobStore(killed), JobStore(clean)
    a, b = a_store.readings(1), b_store.readings(1)
    keys = [(r.angle_index, r.light, r.sensor) for r in a]
    assert len(keys) == len(set(keys)) == len(b)  # nothing lost, nothing duplicated
    assert keys == [(r.angle_index, r.light, r.sensor) for r in b]
    steps = a_store.steps(1)
    assert [(s.angle_index, s.round, s.specimen_deg) for s in steps] == \
        [(s.angle_index, s.round, s.specimen_deg) for s in b_store.steps(1)]
    # On the full turn it chose: the first round, then the fill, each angle once.
    assert sorted(s.specimen_deg for s in steps if s.round == 0) == pytest.approx(
        sorted(first_round_angles(0.0, 8, 1)))
    assert sorted(s.specimen_deg for s in steps if s.round == 1) == pytest.approx(
        fill_angles(0.0, 8, 1))
    assert all(s.done for s in steps) and len(steps) == 16
    events = [e for e in a_store.events_after(0, job_id=1) if e.type == ARC_TEST_EVENT]
    assert len(events) == 1 and events[0].data["arc_deg"] == 360.0
    if tested is not None:
        assert events[0].data == tested.data


def test_sigkill_in_the_refinement_keeps_every_reading_once_and_the_basis(
        tmp_path: Path) -> None:
    killed, clean = tmp_path / "killed.sqlite", tmp_path / "clean.sqlite"
    proc = _child(killed, 3, 10, kind="adaptive")
    kill_when_frozen(proc)
    store = JobStore(killed)
    assert store.get_job(1).done_angles == 10
    before = [e.data for e in store.events_after(0, job_id=1) if e.type == "adaptive_round"]
    assert [e["basis"] for e in before] == ["asymmetric"]  # round 2 planned before the kill
    planned = [(s.angle_index, s.round, s.specimen_deg) for s in store.steps(1)]
    assert len(planned) == 12
    assert _child(killed, 3, kind="adaptive").communicate(timeout=300)[0].strip() == "running"
    assert _child(clean, 3, kind="adaptive").communicate(timeout=300)[0].strip() == "running"
    a_store, b_store = JobStore(killed), JobStore(clean)
    a, b = a_store.readings(1), b_store.readings(1)
    keys = [(r.angle_index, r.light, r.sensor) for r in a]
    assert len(keys) == len(set(keys)) == len(b)  # nothing lost, nothing duplicated
    assert keys == [(r.angle_index, r.light, r.sensor) for r in b]
    steps = a_store.steps(1)
    # The resumed job measured the round it had planned, no angle added or read again; the
    # first two rounds are the uninterrupted run's (the refinement's angles depend on the
    # readings' noise, so only their count is compared).
    assert [(s.angle_index, s.round, s.specimen_deg) for s in steps] == planned
    assert [(s.angle_index, s.round, s.specimen_deg) for s in steps if s.round < 2] == \
        [(s.angle_index, s.round, s.specimen_deg) for s in b_store.steps(1) if s.round < 2]
    assert [s.round for s in steps] == [s.round for s in b_store.steps(1)]
    assert sorted(s.specimen_deg for s in steps if s.round == 1) == pytest.approx(
        fill_angles(0.0, 4, 1))
    assert all(s.done for s in steps)
    assert any(s.specimen_deg > 180.0 for s in steps if s.round == 2)
    for st in (a_store, b_store):
        rounds = [e.data for e in st.events_after(0, job_id=1)
                  if e.type in ("adaptive_round", "adaptive_done")]
        assert [e.get("basis") for e in rounds] == ["asymmetric", "asymmetric"]
        assert [e.type for e in st.events_after(0, job_id=1)].count(ARC_TEST_EVENT) == 1
