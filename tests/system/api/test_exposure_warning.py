"""The page's Check plan (the API's dry run) says when the calibration in effect was measured
at another exposure than the plan's: counts are not rescaled between exposures, so such a scan
is off by the ratio, and it was said only in the result's calibration_warning afterwards (the
page's headline read "Calibrated: values in 1/sr"). A real daemon on the simulated rig
(tests/system/api/conftest.py), calibrated by a calibration job."""

from __future__ import annotations

import csv
import io
import json
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import httpx
import pytest

from tests.system.api.conftest import Daemon, export_fits_off
from tests.system.daemon_proc import wait_for

pytestmark = pytest.mark.system


def queue_calibration(c: httpx.Client, exposure_s: float) -> int:
    """Queue a calibration job at ``exposure_s`` (the caller holds the queue); its id."""
    r = c.post("/api/v1/jobs", json={"plan": {
        "kind": "calibration", "rotations": 2, "reference_albedo": 0.99,
        "exposure": {"exposure_s": exposure_s}}})
    assert r.status_code == 201, r.text
    return int(r.json()["id"])


@contextmanager
def held_queue(c: httpx.Client) -> Iterator[None]:
    """The queue held while the body queues jobs (none starts); then every queued job is
    cancelled and the queue released, whatever the body asserted."""
    assert c.post("/api/v1/rig/halt").status_code == 200
    try:
        yield
    finally:
        for job in (j["id"] for j in c.get("/api/v1/jobs", params={"state": "queued"}).json()):
            c.post(f"/api/v1/jobs/{job}/cancel")
        assert c.post("/api/v1/rig/release").status_code == 200


def queue_scan(c: httpx.Client, exposure_s: float, priority: int = 0) -> dict[str, Any]:
    """Queue a two-angle scan at ``exposure_s`` (the caller holds the queue); its row."""
    r = c.post("/api/v1/jobs", json={"plan": {
        "kind": "uniform", "rotations": 2, "exposure": {"exposure_s": exposure_s}},
        "priority": priority})
    assert r.status_code == 201, r.text
    return dict(r.json())


def refused_alike(c: httpx.Client, plan: dict[str, Any], expected: str) -> str:
    """Check plan warns of ``plan``'s exposure with ``expected`` in its words and submission
    refuses it (422) with the same words (one decision makes both); the warning."""
    r = c.post("/api/v1/jobs/dry-run", json={"plan": plan})
    assert r.status_code == 200, r.text
    (w,) = [w for w in r.json()["warnings"] if w.startswith("exposure:")]
    assert expected in w, w
    r = c.post("/api/v1/jobs", json={"plan": plan})
    assert r.status_code == 422, r.text
    assert expected in r.json()["detail"], r.json()
    return str(w)


@pytest.fixture(scope="module")
def calibrated(daemon: Daemon) -> None:
    """The daemon calibrated by a calibration job at the plans' default exposure, 0.01 s."""
    before = daemon.sim.place_white_reference()
    try:
        with daemon.client() as c:
            r = c.post("/api/v1/jobs", json={"plan": {"kind": "calibration", "rotations": 2,
                                                      "reference_albedo": 0.99}})
            assert r.status_code == 201, r.text
            job = r.json()["id"]
            wait_for(lambda: c.get(f"/api/v1/jobs/{job}").json()["state"]
                     in ("completed", "failed"), what="the calibration job")
            assert c.get(f"/api/v1/jobs/{job}").json()["state"] == "completed"
    finally:
        daemon.sim.place_specimen(before.brdf)


def test_check_plan_warns_of_a_calibration_at_another_exposure(
        daemon: Daemon, calibrated: None) -> None:
    with daemon.client() as c:
        same = {"kind": "uniform", "rotations": 4, "exposure": {"exposure_s": 0.01}}
        r = c.post("/api/v1/jobs/dry-run", json={"plan": same})
        assert r.status_code == 200, r.text
        assert not any(w.startswith("exposure:") for w in r.json()["warnings"])
        other = {**same, "exposure": {"exposure_s": 0.5}}
        r = c.post("/api/v1/jobs/dry-run", json={"plan": other})
        assert r.status_code == 200, r.text
        (w,) = [w for w in r.json()["warnings"] if w.startswith("exposure:")]
        assert "was measured at 0.01 s and this scan reads at 0.5 s" in w, w
        assert "off by about 50 times" in w, w


def test_the_colour_of_a_scan_at_another_exposure_says_so(
        daemon: Daemon, calibrated: None) -> None:
    """Such a scan is refused at submission and at its start (below), so the mismatch is
    made here as a calibration replaced under a running scan (a file edited by hand): the
    result and its colour still say it."""
    plan = {"kind": "uniform", "rotations": 2, "exposure": {"exposure_s": 0.01}}
    worker = daemon.app.state.service.worker
    in_effect = worker.calibration
    with export_fits_off(daemon), daemon.client() as c:
        job = c.post("/api/v1/jobs", json={"plan": plan}).json()["id"]
        try:
            wait_for(lambda: c.get(f"/api/v1/jobs/{job}").json()["state"] != "queued",
                     what="the scan's start")
            worker.calibration = lambda: in_effect().model_copy(update={"exposure_s": 0.005})
            wait_for(lambda: c.get(f"/api/v1/jobs/{job}").json()["state"]
                     in ("completed", "failed"), what="the scan")
        finally:
            worker.calibration = in_effect
        r = c.get(f"/api/v1/jobs/{job}/colour")
        assert r.status_code == 200, r.text
        said = r.json()["warnings"]
        # First of the reconstruction's warnings (a 2-angle scan has others: the colour
        # carries all its exports carry).
        w = said[0]
        assert "measured at exposure 0.005 s, this scan at 0.01 s" in w, said
        # The CSV a lab downloads and keeps carries them on every row.
        r = c.get(f"/api/v1/jobs/{job}/colour", params={"format": "csv"})
        assert r.status_code == 200, r.text
        rows = list(csv.DictReader(io.StringIO(r.text)))
        assert rows and {row["warnings"] for row in rows} == {"; ".join(said)}


def test_a_scan_at_another_exposure_is_refused_naming_both_exposures(
        daemon: Daemon, calibrated: None) -> None:
    """It was queued with a warning, and its values came out off by the ratio: the sensors
    are not assumed linear in exposure time (gonio.calibration), so factors measured at
    0.01 s (the calibration job's default exposure) cannot serve a scan at 0.5 s."""
    with daemon.client() as c:
        before = len(c.get("/api/v1/jobs").json())
        r = c.post("/api/v1/jobs", json={"plan": {"kind": "uniform", "rotations": 2,
                                                  "exposure": {"exposure_s": 0.5}}})
        assert r.status_code == 422, r.text
        said = r.json()["detail"]
        assert "reads at exposure 0.5 s" in said and "measured at 0.01 s" in said, said
        assert "calibrate at 0.5 s first" in said, said
        assert len(c.get("/api/v1/jobs").json()) == before  # nothing queued


def test_a_scan_queued_behind_a_calibration_at_its_exposure_is_taken_and_checked_at_start(
        daemon: Daemon, calibrated: None) -> None:
    """Calibrate at 0.02 s, then scan at 0.02 s, queued together: the scan is accepted behind
    the calibration job. Were that calibration cancelled, the scan is refused when it would
    start (the worker checks the calibration in effect again) and nothing moves."""
    with daemon.client() as c:
        assert c.post("/api/v1/rig/halt").status_code == 200
        try:
            cal = c.post("/api/v1/jobs", json={"plan": {
                "kind": "calibration", "rotations": 2, "reference_albedo": 0.99,
                "exposure": {"exposure_s": 0.02}}})
            assert cal.status_code == 201, cal.text
            scan = c.post("/api/v1/jobs", json={"plan": {
                "kind": "uniform", "rotations": 2, "exposure": {"exposure_s": 0.02}}})
            assert scan.status_code == 201, scan.text
            assert c.post(f"/api/v1/jobs/{cal.json()['id']}/cancel").status_code == 200
        finally:
            assert c.post("/api/v1/rig/release").status_code == 200
        job = scan.json()["id"]
        wait_for(lambda: c.get(f"/api/v1/jobs/{job}").json()["state"]
                 in ("completed", "failed"), what="the scan")
        detail = c.get(f"/api/v1/jobs/{job}").json()
        assert detail["state"] == "failed", detail
        assert detail["reason"].startswith(f"not started: job {job} reads at exposure 0.02 s"), (
            detail["reason"])
        assert "measured at 0.01 s" in detail["reason"], detail["reason"]
        assert detail["done_angles"] == 0


def test_check_plan_judges_a_queued_calibration_at_the_scans_priority(
        daemon: Daemon, calibrated: None) -> None:
    """A calibration job at 0.02 s queued at priority 0 runs before a scan at 0.02 s queued at
    0 (the earlier job among equals) but after one at 5 (the queue takes the higher priority
    first): submission accepts the first and refuses the second, so the dry run warns of the
    exposure for the second only, naming the calibration job and its priority. It judged
    every plan at priority 0, and warned "such a scan is refused" of a scan that would run
    behind its calibration."""
    scan = {"kind": "uniform", "rotations": 2, "exposure": {"exposure_s": 0.02}}
    with daemon.client() as c:
        assert c.post("/api/v1/rig/halt").status_code == 200
        cal = None
        try:
            cal = queue_calibration(c, 0.02)
            r = c.post("/api/v1/jobs/dry-run", json={"plan": scan})
            assert r.status_code == 200, r.text
            assert not [w for w in r.json()["warnings"] if w.startswith("exposure:")], r.json()
            r = c.post("/api/v1/jobs/dry-run", json={"plan": scan, "priority": 5})
            assert r.status_code == 200, r.text
            (w,) = [w for w in r.json()["warnings"] if w.startswith("exposure:")]
            assert f"calibration job {cal} is queued at priority 0, below this scan's 5" in w, w
            # Submission at 5 refuses with the same words.
            r = c.post("/api/v1/jobs", json={"plan": scan, "priority": 5})
            assert r.status_code == 422, r.text
            assert f"calibration job {cal} is queued at priority 0" in r.json()["detail"]
            # A priority outside the queue's range is refused as submission refuses it.
            r = c.post("/api/v1/jobs/dry-run", json={"plan": scan, "priority": 5000})
            assert r.status_code == 422, r.text
            assert "priority" in r.text, r.text
        finally:
            if cal is not None:
                c.post(f"/api/v1/jobs/{cal}/cancel")
            assert c.post("/api/v1/rig/release").status_code == 200


def test_a_scan_behind_a_calibration_at_another_exposure_is_refused_at_once(
        daemon: Daemon, calibrated: None) -> None:
    """The calibration in effect is at 0.01 s; a calibration job at 0.02 s is queued before a
    scan at 0.01 s. When the scan starts the calibration in effect is that job's, at 0.02 s,
    and the worker refuses it (counts are not rescaled between exposures). It was accepted,
    waited its turn and failed "not started"; it is refused at submission now, naming the
    calibration job, and Check plan says so."""
    scan = {"kind": "uniform", "rotations": 2, "exposure": {"exposure_s": 0.01}}
    with daemon.client() as c:
        before = len(c.get("/api/v1/jobs").json())
        with held_queue(c):
            cal = queue_calibration(c, 0.02)
            w = refused_alike(c, scan, f"this plan reads at exposure 0.01 s and calibration "
                                       f"job {cal}, which runs before it, measures at 0.02 s")
            assert "queue a calibration at 0.01 s first" in w, w
            # Queued above the calibration's priority it runs first, under the calibration in
            # effect now (0.01 s): accepted, and Check plan at that priority says nothing.
            r = c.post("/api/v1/jobs/dry-run", json={"plan": scan, "priority": 5})
            assert not [w for w in r.json()["warnings"] if w.startswith("exposure:")], r.json()
            r = c.post("/api/v1/jobs", json={"plan": scan, "priority": 5})
            assert r.status_code == 201, r.text
            # At the queued calibration's exposure: queued behind it.
            r = c.post("/api/v1/jobs", json={"plan": {**scan, "exposure": {
                "exposure_s": 0.02}}})
            assert r.status_code == 201, r.text
        # The refused scan was not queued: the calibration and the two accepted scans were.
        assert len(c.get("/api/v1/jobs").json()) == before + 3


def test_the_last_calibration_ahead_decides_the_exposure(daemon: Daemon, calibrated: None) -> None:
    """Two calibration jobs queued before a scan, at 0.01 s and then at 0.02 s: the one in
    effect when the scan starts is the second, so a scan at 0.01 s would be refused when it
    starts. It was accepted because one calibration ahead (the first) measured at 0.01 s.
    Submission now refuses it naming the last calibration, Check plan says the same, a scan
    at the last one's exposure is accepted, and moving the 0.01 s calibration behind the other
    (the queue's order) makes the 0.01 s scan acceptable again."""
    scan = {"kind": "uniform", "rotations": 2, "exposure": {"exposure_s": 0.01}}
    with daemon.client() as c:
        before = len(c.get("/api/v1/jobs").json())
        with held_queue(c):
            first = queue_calibration(c, 0.01)
            last = queue_calibration(c, 0.02)
            refused_alike(c, scan, f"this plan reads at exposure 0.01 s and calibration job "
                                   f"{last}, the last of the 2 calibration jobs that run before "
                                   "it, measures at 0.02 s")
            # At an exposure neither the calibration in effect (0.01 s) nor the last one ahead
            # measures at, the refusal names the one that will be in effect, not the one now.
            refused_alike(c, {**scan, "exposure": {"exposure_s": 0.5}},
                          f"calibration job {last}, the last of the 2")
            # At the last calibration's exposure: accepted.
            r = c.post("/api/v1/jobs", json={"plan": {**scan, "exposure": {
                "exposure_s": 0.02}}})
            assert r.status_code == 201, r.text
            at_last = r.json()["id"]
            # The 0.01 s calibration moved to run after the 0.02 s one would leave that scan
            # under 0.01 s: refused while it is queued; once it is cancelled, done.
            r = c.post(f"/api/v1/jobs/{first}/reorder", json={"position": 1})
            assert r.status_code == 409, r.text
            assert f"job {at_last} reads at exposure 0.02 s" in r.json()["detail"], r.json()
            assert c.post(f"/api/v1/jobs/{at_last}/cancel").status_code == 200
            r = c.post(f"/api/v1/jobs/{first}/reorder", json={"position": 1})
            assert r.status_code == 200, r.text
            order = [j["id"] for j in c.get("/api/v1/jobs", params={"state": "queued"}).json()]
            assert order.index(last) < order.index(first), order
            r = c.post("/api/v1/jobs/dry-run", json={"plan": scan})
            assert not [w for w in r.json()["warnings"] if w.startswith("exposure:")], r.json()
            r = c.post("/api/v1/jobs", json={"plan": scan})
            assert r.status_code == 201, r.text
        # Two calibrations and two accepted scans were queued; the refused ones were not.
        assert len(c.get("/api/v1/jobs").json()) == before + 4


def test_a_reorder_that_would_start_a_scan_under_another_exposure_is_refused(
        daemon: Daemon, calibrated: None) -> None:
    """A scan at 0.01 s queued under the calibration in effect (0.01 s), and a calibration job
    at 0.02 s queued behind it: moving the calibration ahead of the scan made the scan start
    under 0.02 s factors, which the worker refuses ("not started", long after the move). The
    move is refused (409) naming the scan and both exposures, and changes nothing; so is
    moving a 0.02 s scan from behind the calibration ahead of it; a move that keeps every
    scan under its own exposure is done."""
    with daemon.client() as c, held_queue(c):
        r = c.post("/api/v1/jobs", json={"plan": {
            "kind": "uniform", "rotations": 2, "exposure": {"exposure_s": 0.01}}})
        assert r.status_code == 201, r.text
        scan = r.json()["id"]
        cal = queue_calibration(c, 0.02)
        r = c.post("/api/v1/jobs", json={"plan": {
            "kind": "uniform", "rotations": 2, "exposure": {"exposure_s": 0.02}}})
        assert r.status_code == 201, r.text
        later = r.json()["id"]

        def order() -> list[int]:
            return [j["id"] for j in c.get("/api/v1/jobs", params={"state": "queued"}).json()
                    if j["id"] in (scan, cal, later)]

        assert order() == [scan, cal, later]
        r = c.post(f"/api/v1/jobs/{cal}/reorder", json={"position": 0})
        assert r.status_code == 409, r.text
        detail = r.json()["detail"]
        assert f"job {scan} reads at exposure 0.01 s and calibration job {cal}" in detail
        assert "measures at 0.02 s" in detail and "refused when it starts" in detail, detail
        r = c.post(f"/api/v1/jobs/{cal}/reorder", json={"priority": 5})
        assert r.status_code == 409, r.text
        assert order() == [scan, cal, later]
        # The 0.02 s scan moved ahead of the calibration would start under 0.01 s.
        r = c.post(f"/api/v1/jobs/{later}/reorder", json={"position": 0})
        assert r.status_code == 409, r.text
        assert (f"job {later} reads at exposure 0.02 s and the calibration in effect was "
                "measured at 0.01 s") in r.json()["detail"], r.json()
        assert order() == [scan, cal, later]
        # The 0.01 s scan moved to the end would start under 0.02 s: refused; moved
        # nowhere new (position 0, where it is) it is done.
        r = c.post(f"/api/v1/jobs/{scan}/reorder", json={"position": 2})
        assert r.status_code == 409, r.text
        r = c.post(f"/api/v1/jobs/{scan}/reorder", json={"position": 0})
        assert r.status_code == 200, r.text
        assert order() == [scan, cal, later]


def test_a_queued_scan_its_calibration_was_cancelled_from_says_it_will_be_refused(
        daemon: Daemon, calibrated: None) -> None:
    """A scan at 0.02 s queued behind a calibration job at 0.02 s (the one in effect is at
    0.01 s): accepted. The calibration cancelled, the scan would start under 0.01 s and the
    worker would refuse it at its turn ("not started"), which nothing said while it waited.
    Its row in the job list and its detail now say so (start_refusal), naming both exposures
    and what to do; a scan that will start fine says nothing, and queueing a calibration at
    0.02 s before it again clears it."""
    with daemon.client() as c, held_queue(c):
        cal = queue_calibration(c, 0.02)
        row = queue_scan(c, 0.02)
        scan = row["id"]
        assert row["start_refusal"] is None
        fine = queue_scan(c, 0.01, priority=5)["id"]

        def refusals() -> dict[int, str | None]:
            return {j["id"]: j["start_refusal"] for j in c.get("/api/v1/jobs").json()
                    if j["id"] in (scan, fine)}

        assert refusals() == {scan: None, fine: None}
        assert c.post(f"/api/v1/jobs/{cal}/cancel").status_code == 200
        said = refusals()
        assert said[fine] is None, said
        expected = ("would be refused when it starts, as the queue stands: it reads at "
                    "exposure 0.02 s and the "
                    "calibration in effect was measured at 0.01 s")
        assert said[scan] is not None and said[scan].startswith(expected), said
        assert c.get(f"/api/v1/jobs/{scan}").json()["start_refusal"] == said[scan]
        # A calibration at 0.02 s queued at the scan's priority runs after it (the earlier
        # job among equals): still said. Moved ahead of it (after the 0.01 s scan, at 5):
        # nothing to say.
        again = queue_calibration(c, 0.02)
        assert refusals()[scan] == said[scan]
        r = c.post(f"/api/v1/jobs/{again}/reorder", json={"position": 1})
        assert r.status_code == 200, r.text
        assert refusals() == {scan: None, fine: None}


def test_gonio_jobs_cancel_and_remove_say_which_queued_scan_would_now_be_refused(
        daemon: Daemon, calibrated: None, capsys: pytest.CaptureFixture[str]) -> None:
    """``gonio jobs --daemon URL cancel`` of the calibration a queued scan at another exposure
    waited for said only "cancelled": the scan's row said it would be refused, but the
    command that decided it did not. cancel (and remove) now name the scan and both
    exposures; cancelling a job that leaves every scan fine says nothing more."""
    from gonio.cli import main

    base = ["jobs", "--daemon", daemon.url, "--api-key", daemon.key]
    with daemon.client() as c, held_queue(c):
        cal = queue_calibration(c, 0.02)
        scan = queue_scan(c, 0.02)["id"]
        # Ahead of the 0.02 s calibration, under today's 0.01 s one.
        other = queue_scan(c, 0.01, priority=5)["id"]
        capsys.readouterr()
        # The 0.01 s scan cancelled: the 0.02 s one still starts under its calibration.
        assert main([*base, "cancel", str(other)]) == 0
        out = capsys.readouterr()
        assert f"job {other} cancelled" in out.out and "refused" not in out.err, out
        assert main([*base, "cancel", str(cal)]) == 0
        out = capsys.readouterr()
        assert f"job {cal} cancelled" in out.out, out
        assert (f"note: job {scan} would be refused when it starts, as the queue stands: it "
                "reads at exposure 0.02 s") in out.err, out.err
        assert "0.01 s" in out.err, out.err
        # remove says it too, of the cancelled calibration's queue; with --json as well, on
        # stderr, stdout holding the one JSON answer a script parses.
        assert main([*base, "remove", str(cal), "--json"]) == 0
        out = capsys.readouterr()
        assert json.loads(out.out) == {"id": cal, "removed": True}, out.out
        assert f"note: job {scan} would be refused" in out.err, out.err
        # cancel --json alike: a new 0.02 s calibration makes the scan fine, cancelling it
        # makes it refused again.
        cal = queue_calibration(c, 0.02)
        capsys.readouterr()
        assert main([*base, "cancel", str(cal), "--json"]) == 0
        out = capsys.readouterr()
        assert json.loads(out.out)["reason"] == "cancelled before it started", out.out
        assert f"note: job {scan} would be refused" in out.err, out.err
