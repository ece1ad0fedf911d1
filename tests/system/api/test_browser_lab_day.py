"""The lab page through a lab's day (issue 27): a stale API key, an uncalibrated scan, what the
page says about calibration, time and angles. Headless Chromium against the real daemon on the
simulated rig (tests/system/api/conftest.py), as tests/system/api/test_browser.py."""

from __future__ import annotations

import time
from collections.abc import Iterator
from typing import Any

import pytest

from gonio.calibration import CALIBRATION_FILE, Calibration, PairCalibration, save_calibration
from gonio.paths import scan_data_dir
from tests.system.api.conftest import Daemon, export_fits_off
from tests.system.api.test_browser import (  # noqa: F401 (fixture)
    _severe,
    browser,
    click_when_steady,
    load_page,
    open_live,
)
from tests.system.api.test_scan_flow import ENDED, wait_state

pytestmark = [pytest.mark.system, pytest.mark.timeout(600)]

PLAN = {"kind": "uniform", "specimen": "felt", "rotations": 4,
        "exposure": {"exposure_s": 0.005}}


def _row_ids(browser: Any) -> list[str]:  # noqa: F811 (the fixture's name)
    return list(browser.execute_script(
        "return [...document.querySelectorAll('#jobs tr[data-id]')].map(r => r.dataset.id)"))


def _text(browser: Any, element_id: str) -> str:  # noqa: F811 (the fixture's name)
    return str(browser.execute_script(
        "return document.getElementById(arguments[0])?.textContent ?? ''", element_id))


@pytest.fixture(scope="module")
def finished_job(daemon: Daemon) -> int:
    """One short scan run to its end through the API (its id), made once for the tests that
    need a row in the queue or a measured reconstruction. Its export fits are not under test
    (none of these tests opens an export): it finishes without them."""

    with export_fits_off(daemon), daemon.client() as c:
        job = int(c.post("/api/v1/jobs", params={"accept_uncalibrated": "true"},
                         json={"plan": PLAN}).json()["id"])
        wait_state(c, job, ENDED, timeout=300)
    return job


def test_a_stale_key_gets_a_prompt_and_the_new_address_in_the_same_tab_recovers(
    daemon: Daemon, browser: Any, finished_job: int  # noqa: F811
) -> None:
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import WebDriverWait

    wait = WebDriverWait(browser, 300, poll_frequency=0.2)
    job = finished_job  # the queue is not empty
    # The tab holds a key this daemon does not accept (another data directory's, a
    # --throwaway start's, or one from before sim-session.key was deleted).
    load_page(browser, f"{daemon.url}/#key={'0' * 48}")
    wait.until(lambda d: d.find_element(By.ID, "key-prompt").is_displayed())
    prompt = browser.find_element(By.ID, "key-prompt").text
    assert "does not accept the API key of this tab" in prompt, prompt
    # Where to find the right key, without claiming a restart changes it: a restarted
    # `gonio serve --sim` keeps its key on one data directory (sim-session.key).
    assert "the address the daemon printed at its start" in prompt, prompt
    assert "prints a new key" not in prompt, prompt
    assert browser.find_element(By.ID, "key-state").text == "key refused by this daemon"
    # It never claims there are no jobs: it could not read them.
    assert not browser.find_element(By.ID, "no-jobs").is_displayed()
    assert _row_ids(browser) == []
    # The user pastes the new address (`#key=NEW`) into the same tab: only the fragment
    # changes, no reload; the page takes the key and shows the queue.
    browser.execute_script("location.hash = arguments[0]", f"#key={daemon.key}")
    wait.until(lambda d: str(job) in _row_ids(d))
    wait.until(lambda d: d.find_element(By.ID, "live-chip").text == "live")
    assert not browser.find_element(By.ID, "key-prompt").is_displayed()
    assert browser.execute_script("return sessionStorage.getItem('gonio.apiKey')") == daemon.key
    assert "#key" not in browser.current_url


@pytest.fixture
def calibrated_elsewhere(daemon: Daemon) -> Iterator[None]:
    """The rig's calibration in `gonio scan`'s data directory, not in this daemon's."""
    cfg = daemon.sim.config
    own = scan_data_dir(cfg)
    own.mkdir(parents=True, exist_ok=True)
    save_calibration(Calibration(
        pairs=tuple(PairCalibration(light=p.light, sensor=p.sensor, factor=(1e-3,) * 3)
                    for p in cfg.pair_list()),
        reference_albedo=0.99, source="job 1: white reference"), own / CALIBRATION_FILE)
    try:
        yield
    finally:
        (own / CALIBRATION_FILE).unlink()


def test_an_uncalibrated_scan_is_warned_accepted_and_labelled_as_such(
    daemon: Daemon, browser: Any, calibrated_elsewhere: None,  # noqa: F811
    no_export_fits: None,
) -> None:
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support import expected_conditions as ec
    from selenium.webdriver.support.ui import Select

    browser.get_log("browser")  # drop what earlier tests left (a stale key's 403s)
    wait = open_live(browser, daemon, 300)
    with daemon.client() as c:
        assert c.get("/api/v1/calibration").json()["source"] == "none"
    form = browser.find_element(By.ID, "scan-form")
    Select(form.find_element(By.NAME, "kind")).select_by_value("uniform")
    rotations = form.find_element(By.NAME, "rotations")
    rotations.clear()
    rotations.send_keys("4")
    exposure = form.find_element(By.NAME, "exposure_s")
    exposure.clear()
    exposure.send_keys("0.005")
    # Check plan: not a bare "OK", and the warning says the values will be sensor units.
    click_when_steady(wait, "#dry-run")
    wait.until(lambda d: d.find_element(By.ID, "dry-run-warnings").is_displayed())
    assert not browser.find_element(By.ID, "dry-run-result").text.startswith("OK")
    warnings = browser.find_element(By.ID, "dry-run-warnings").text
    assert "uncalibrated" in warnings and "sensor units" in warnings, warnings
    before = set(_row_ids(browser))
    # Start: the daemon refuses an uncalibrated scan of a calibrated rig; the page asks.
    click_when_steady(wait, "#start-scan")
    alert = wait.until(ec.alert_is_present())
    assert "uncalibrated" in alert.text and str(scan_data_dir(daemon.sim.config)) in alert.text
    alert.dismiss()
    wait.until(lambda d: "Not started" in d.find_element(By.ID, "dry-run-result").text)
    assert set(_row_ids(browser)) == before
    click_when_steady(wait, "#start-scan")
    wait.until(ec.alert_is_present()).accept()
    wait.until(lambda d: set(_row_ids(d)) - before)
    (job,) = set(_row_ids(browser)) - before
    # The table is redrawn on every event: read the row's state in one script call.
    wait.until(lambda d: d.execute_script(
        "return document.querySelector(`#jobs tr[data-id='${arguments[0]}']`)?.dataset.state",
        job) == "completed")
    # Every place that reads the numbers says they are not the material's. (Read in one script
    # call each: the result panel is redrawn as events arrive.)
    wait.until(lambda d: _text(d, "headline-calibration") != "")
    assert _text(browser, "headline-calibration").startswith("Uncalibrated")
    wait.until(lambda d: "Uncalibrated" in _text(d, "readings-caption"))
    assert "the calibrated samples" not in _text(browser, "readings-caption")
    wait.until(lambda d: "Uncalibrated" in _text(d, "render-caption"))
    assert "Uncalibrated" in _text(browser, "preview-caption")
    # A half-turn scan's plot spans half a turn (its angles are 0, 45, 90, 135 degrees).
    x = browser.execute_script(
        "const s = Chart.getChart(document.getElementById('readings-plot')).options.scales.x;"
        "return [s.min, s.max, s.title.text]")
    assert x == [0, 180, "specimen angle (degrees)"], x
    # The metrics say what they mean, not only their keys.
    rows = browser.execute_script(
        "return [...document.querySelectorAll('#metrics th')].map(t => t.textContent)")
    cv = [r for r in rows if r.startswith("cv_log_error")]
    assert cv and "leave-one-pair-out" in cv[0], rows
    assert [e for e in _severe(browser) if "409" not in e["message"]] == []


def test_the_stage_chip_gives_the_specimen_angle_and_a_long_eta_keeps_the_buttons_in_view(
    daemon: Daemon, browser: Any, finished_job: int,  # noqa: F811 (a row with its buttons)
) -> None:
    from selenium.webdriver.common.by import By

    wait = open_live(browser, daemon, 120)
    with daemon.client() as c:
        # One and a half turns and a bit: the stage's position is not the specimen's angle.
        r = c.post("/api/v1/rig/stage", json={"action": "move", "angle_deg": 528.75})
        assert r.status_code == 200, r.text
    # 528.75 - 360 = 168.75 degrees (shown to 0.1 degree).
    wait.until(lambda d: d.find_element(By.ID, "stage-chip").text.startswith("specimen at 168.8°"))
    assert "528.75" in browser.find_element(By.ID, "stage-chip").get_attribute("title")
    # A first scan's activity is long ("building the BRDF training library ..."): it wraps in
    # its cell; the row's buttons stay inside the queue's box.
    wait.until(lambda d: d.execute_script("return document.querySelector('#jobs tr td.eta')"))
    inside = browser.execute_script("""
        const row = document.querySelector('#jobs tr[data-id]');
        row.querySelector('td.eta').textContent =
          'building the BRDF training library, 74 of 175 materials (about 2 min, once per install)';
        const box = document.getElementById('queue').getBoundingClientRect();
        const last = row.lastElementChild.getBoundingClientRect();
        return [last.right <= box.right + 0.5, document.getElementById('queue').scrollWidth
                <= document.getElementById('queue').clientWidth + 1];""")
    assert inside == [True, True], inside


def _seconds(text: str) -> float:
    """A time as the page writes it ("40 s", "3 min", "1.5 h") in seconds."""
    number, unit = text.split()
    return float(number) * {"s": 1, "min": 60, "h": 3600}[unit]


def test_the_eta_covers_reconstruction_with_a_measured_estimate_and_keeps_abort_in_view(
    daemon: Daemon, browser: Any, no_export_fits: None,  # noqa: F811
    finished_job: int,  # at least one reconstruction measured on this daemon
) -> None:
    """Issue 27: the ETA left out reconstruction ("N min measuring, then reconstruction").
    It now adds an estimate of it from the last scans' measured finishing times, says it is
    an estimate, and still wraps so the Abort button stays on screen in a narrower window."""
    import re
    import statistics

    browser.set_window_size(1024, 1600)
    try:
        wait = open_live(browser, daemon, 300)
        with daemon.client() as c:
            # The independent expectation: the median finishing time ("seconds" in each
            # completed scan's summary) of the newest three completed scans.
            done = sorted(j["id"] for j in c.get("/api/v1/jobs", params={
                "state": "completed"}).json() if j["kind"] != "calibration")
            secs = [c.get(f"/api/v1/jobs/{i}").json()["result"]["seconds"] for i in done]
            expected = statistics.median(secs[-3:])
            # 20 averaged exposures per reading (1 s of sim time, 0.1 s here at time scale
            # 10): a scan that measures for a while, so its ETA is on the page.
            plan = {**PLAN, "rotations": 12, "exposure": {"exposure_s": 0.05, "averages": 20}}
            job = c.post("/api/v1/jobs", params={"accept_uncalibrated": "true"},
                         json={"plan": plan}).json()["id"]
            try:
                def eta_text(d: Any) -> str:
                    d.execute_script(
                        "document.querySelector(`#jobs tr[data-id='${arguments[0]}']`)"
                        "?.click()", job)
                    return str(d.execute_script(
                        "return document.querySelector(`#jobs tr[data-id='${arguments[0]}']"
                        " td.eta`)?.textContent ?? ''", job))

                # The text the wait saw is the one checked: a second read raced a redraw of
                # the queue beside a busy CPU and read an empty cell (once, in a full run).
                text = wait.until(lambda d: t if "left in all" in (t := eta_text(d)) else None)
                detail = c.get(f"/api/v1/jobs/{job}").json()
                assert detail["reconstruction_s"] == pytest.approx(expected)
                assert f"jobs {', '.join(map(str, done[-3:]))}" in detail[
                    "reconstruction_estimate"] or len(done) == 1
                assert detail["time_left_s"] == pytest.approx(
                    detail["eta_s"] + (detail["basis_build_s"] or 0) + expected, abs=1.0)
                t_ = r"([\d.]+ (?:s|min|h))"
                m = re.search(rf"≈ {t_} left in all \(est\.\): measuring {t_}"
                              rf".* reconstruction ≈ {t_}", text)
                assert m, text
                total, measuring, recon = (_seconds(g) for g in m.groups())
                # Shown rounded (to 1 s, or 1 min past 90 s).
                assert recon == pytest.approx(expected, abs=30 if expected >= 90 else 0.51)
                assert total >= measuring + recon - 61, text
                # The tooltip says what the estimate rests on.
                def eta_title(d: Any) -> str:
                    return str(d.execute_script(
                        "return document.querySelector(`#jobs tr[data-id='${arguments[0]}']"
                        " td.eta`)?.title ?? ''", job))

                title = wait.until(lambda d: t if (t := eta_title(d)) else None)
                assert title.startswith("reconstruction estimate:"), title
                # The cell wraps: Abort stays inside the window and the queue's box.
                inside = browser.execute_script("""
                    const row = document.querySelector(`#jobs tr[data-id='${arguments[0]}']`);
                    const abort = row.querySelector('button[data-action="abort"]');
                    if (!abort) return null;
                    const b = abort.getBoundingClientRect();
                    const box = document.getElementById('queue').getBoundingClientRect();
                    return [b.right <= window.innerWidth, b.right <= box.right + 0.5,
                            document.documentElement.scrollWidth <= window.innerWidth];""", job)
                assert inside in (None, [True, True, True]), inside
                if inside is None:  # the job ended meanwhile; check with the text forced
                    pytest.fail("the job ended before its Abort button could be checked")
            finally:
                c.post(f"/api/v1/jobs/{job}/abort")
                wait_state(c, job, ENDED, timeout=120)
    finally:
        browser.set_window_size(1280, 1600)


def test_a_running_jobs_buttons_stay_in_the_queues_box_beside_a_long_specimen_name(
    daemon: Daemon, browser: Any, no_export_fits: None,  # noqa: F811
) -> None:
    """A specimen name does not wrap (nor do other cells' words), so a long one made the jobs
    table wider than the queue's box, which scrolls sideways: the running job's Pause and Abort
    buttons sat past its right edge, out of view until the lab scrolled the table (a helper
    saw it with a completed adaptive job's row at a 1024 px window). The buttons' column stays
    in the box's view."""
    browser.set_window_size(1024, 1600)
    try:
        wait = open_live(browser, daemon, 300)
        long_name = "brushed-aluminium-panel-A7-lot-2026-11-29-holder-3-second-mounting"
        with daemon.client() as c:
            plan = {**PLAN, "specimen": long_name, "rotations": 12,
                    "exposure": {"exposure_s": 0.05, "averages": 20}}
            job = c.post("/api/v1/jobs", params={"accept_uncalibrated": "true"},
                         json={"plan": plan}).json()["id"]
            try:
                def abort_box(d: Any) -> Any:
                    return d.execute_script("""
                        const row = document.querySelector(`#jobs tr[data-id='${arguments[0]}']`);
                        const abort = row?.querySelector('button[data-action="abort"]');
                        if (!abort) return null;
                        const q = document.getElementById('queue');
                        const b = abort.getBoundingClientRect();
                        const hit = document.elementFromPoint((b.left + b.right) / 2,
                                                              (b.top + b.bottom) / 2);
                        return {wider: q.scrollWidth > q.clientWidth, right: b.right,
                                box: q.getBoundingClientRect().right,
                                on_top: hit === abort || abort.contains(hit)};""", job)

                seen = wait.until(abort_box)
                # The name does widen the table past the box (else this checks nothing) ...
                assert seen["wider"], seen
                # ... and the button is still inside the box's view.
                assert seen["right"] <= seen["box"] + 0.5, seen
                assert seen["on_top"], seen  # nothing drawn over it: a click reaches it
            finally:
                c.post(f"/api/v1/jobs/{job}/abort")
                wait_state(c, job, ENDED, timeout=120)
                # Its wide row would stay in the queue of the module's later tests.
                assert c.delete(f"/api/v1/jobs/{job}").status_code == 204
    finally:
        browser.set_window_size(1280, 1600)


def test_an_adaptive_jobs_progress_only_fills_and_says_its_round(
    daemon: Daemon, browser: Any, no_export_fits: None  # noqa: F811
) -> None:
    """Issue 27: an adaptive job showed "4/8" while its bar filled, reset when a round added
    angles, and filled again. Its bar now runs against the most angles the plan can reach
    (the dry run's max_angles, also the job's max_angles in the API), so it only fills; the
    round is said beside it."""
    import time

    wait = open_live(browser, daemon, 300)
    plan = {"kind": "adaptive", "specimen": "rounds", "rule": "vf", "threshold": 0.001,
            "initial_rotations": 4, "max_rotations": 12, "span_deg": 180,
            "exposure": {"exposure_s": 0.005}}
    # Every 50 ms, the adaptive row's progress as drawn: [value, max, text, state].
    browser.execute_script("""
        window.__progress = [];
        window.__watch = setInterval(() => {
          const row = [...document.querySelectorAll('#jobs tr[data-id]')]
            .find((r) => r.children[1].textContent === 'rounds');
          const bar = row?.querySelector('progress');
          if (bar) window.__progress.push([bar.value, bar.max,
            bar.parentElement.textContent, row.dataset.state]);
          if (row) row.click();  // selected: its detail (and round) is polled
        }, 50);""")
    with daemon.client() as c:
        bound = c.post("/api/v1/jobs/dry-run", json={"plan": plan}).json()["max_angles"]
        job = c.post("/api/v1/jobs", params={"accept_uncalibrated": "true"},
                     json={"plan": plan}).json()["id"]
        deadline = time.monotonic() + 300
        while (row := c.get(f"/api/v1/jobs/{job}").json())["state"] not in (
                "completed", "failed", "aborted"):
            assert time.monotonic() < deadline, "the adaptive scan did not end"
            time.sleep(0.2)
        assert row["state"] == "completed", row
        assert row["max_angles"] == bound
        listed = next(j for j in c.get("/api/v1/jobs").json() if j["id"] == job)
        assert listed["max_angles"] == bound
    assert row["total_angles"] > 4, "the plan did not refine: nothing to test"
    wait.until(lambda d: any(s[3] == "completed" for s in d.execute_script(
        "return window.__progress")))
    samples = browser.execute_script("clearInterval(window.__watch); return window.__progress")
    measuring = [s for s in samples if s[3] in ("running", "suspended", "paused")]
    assert measuring, samples
    # One scale while it measures: the plan's bound, never the round's planned angles.
    assert {s[1] for s in measuring} == {bound}, sorted({s[1] for s in measuring})
    values = [s[0] for s in measuring]
    assert values == sorted(values), values  # only fills
    assert all(f"of ≤{bound} angles" in s[2] for s in measuring), measuring[-1]
    assert any("round 2" in s[2] for s in measuring), sorted({s[2] for s in measuring})
    # Completed: a full bar and the angles it took.
    last = samples[-1]
    assert last[0] == last[1] and f"{row['done_angles']} angles" in last[2], last


def _scan_to_the_end(daemon: Daemon, specimen: str) -> int:
    """One more short scan (``PLAN``), run to completion through the API: its id."""
    import time

    with export_fits_off(daemon), daemon.client() as c:
        job = int(c.post("/api/v1/jobs", params={"accept_uncalibrated": "true"},
                         json={"plan": {**PLAN, "specimen": specimen}}).json()["id"])
        deadline = time.monotonic() + 300
        while (state := c.get(f"/api/v1/jobs/{job}").json()["state"]) not in (
                "completed", "failed", "aborted"):
            assert time.monotonic() < deadline, "the scan did not end"
            time.sleep(0.2)
    assert state == "completed", state
    return job


def test_another_jobs_rendering_is_not_shown_while_this_ones_is_made(
    daemon: Daemon, browser: Any, finished_job: int  # noqa: F811
) -> None:
    """A rendering takes seconds (8-13 s on a busy 2-core machine), and the page kept showing
    the previously selected job's picture under the new job's heading until it came, with only
    the caption saying "Rendering…". Here the second job's rendering is held back in the page's
    fetch: meanwhile no picture is shown; once it arrives, it is."""
    from selenium.webdriver.common.by import By

    other = _scan_to_the_end(daemon, "second")
    wait = open_live(browser, daemon, 300)

    def rendered(d: Any) -> bool:
        return bool(d.execute_script(
            "const img = document.getElementById('render');"
            "return !img.hidden && img.complete && img.naturalWidth > 0 && "
            "!document.getElementById('render-caption').textContent.startsWith('Rendering')"))

    click_when_steady(wait, f"#jobs tr[data-id='{finished_job}']")
    wait.until(lambda d: _text(d, "result-job") == f"job {finished_job} (completed)")
    wait.until(rendered)
    # From now on the page's requests for a rendering wait until the test lets them go.
    browser.execute_script("""
        const fetchNow = window.fetch;
        window.__held = [];
        window.fetch = (url, init) => String(url).includes('render.png')
          ? new Promise((done) => window.__held.push(() => done(fetchNow(url, init))))
          : fetchNow(url, init);""")
    click_when_steady(wait, f"#jobs tr[data-id='{other}']")
    wait.until(lambda d: _text(d, "result-job") == f"job {other} (completed)")
    wait.until(lambda d: d.execute_script("return window.__held.length") > 0)
    assert _text(browser, "render-caption").startswith("Rendering")
    assert not browser.find_element(By.ID, "render").is_displayed(), \
        f"job {finished_job}'s rendering is shown as job {other}'s"
    browser.execute_script("window.__held.splice(0).forEach((go) => go())")
    wait.until(rendered)


def _asked_then_confirmed(wait: Any, button: str, phrases: tuple[str, ...],
                          unchanged: Any) -> None:
    """Click ``button``: the page asks first, its question holding every phrase; dismissed,
    ``unchanged()`` (its own assertions) holds; clicked again, the question is accepted."""
    from selenium.webdriver.support import expected_conditions as ec

    click_when_steady(wait, button)
    alert = wait.until(ec.alert_is_present())
    question = alert.text
    for phrase in phrases:
        assert phrase in question, question
    alert.dismiss()
    unchanged()
    click_when_steady(wait, button)
    wait.until(ec.alert_is_present()).accept()


def test_removing_a_job_asks_first_and_says_what_is_lost(
    daemon: Daemon, browser: Any  # noqa: F811
) -> None:
    """"remove" deleted a job and its stored readings at one click: no result can be shown,
    exported or rebuilt after that. The page now asks, saying so; dismissed, nothing goes."""
    # A job that ends without moving anything: queued behind a halt, then cancelled (aborted).
    with daemon.client() as c:
        assert c.post("/api/v1/rig/halt").status_code == 200
        try:
            job = int(c.post("/api/v1/jobs", params={"accept_uncalibrated": "true"},
                             json={"plan": {**PLAN, "specimen": "to remove"}}).json()["id"])
            assert c.post(f"/api/v1/jobs/{job}/cancel").json()["state"] == "aborted"
        finally:
            assert c.post("/api/v1/rig/release").status_code == 200
    wait = open_live(browser, daemon, 120)

    def still_there() -> None:
        with daemon.client() as c:
            assert c.get(f"/api/v1/jobs/{job}").status_code == 200

    _asked_then_confirmed(wait, f"#jobs tr[data-id='{job}'] button[data-action='remove']",
                          (f"Remove job {job} (to remove)?", "readings are deleted for good",
                           "rebuild"), still_there)
    wait.until(lambda d: str(job) not in _row_ids(d))
    with daemon.client() as c:
        assert c.get(f"/api/v1/jobs/{job}").status_code == 404


def _paused_long_job(daemon: Daemon, specimen: str) -> int:
    """A long scan started and paused at once (it holds the rig until resumed or aborted)."""
    import time

    long = {**PLAN, "specimen": specimen, "rotations": 400}
    with daemon.client() as c:
        job = int(c.post("/api/v1/jobs", params={"accept_uncalibrated": "true"},
                         json={"plan": long}).json()["id"])
        deadline = time.monotonic() + 120
        while c.get(f"/api/v1/jobs/{job}").json()["state"] != "running":
            assert time.monotonic() < deadline, "the long scan did not start"
            time.sleep(0.05)
        assert c.post(f"/api/v1/jobs/{job}/pause", params={"immediate": "true"}
                      ).status_code == 200
    return job


def test_a_queued_job_behind_a_paused_one_says_what_it_waits_for(
    daemon: Daemon, browser: Any, no_export_fits: None  # noqa: F811
) -> None:
    """A paused job holds the rig, and the queue waits behind it (after a restart too, or a
    `gonio scan` interrupted by Ctrl-C in the same data directory): the queued row said only
    "queued", with no word of why nothing started."""

    from selenium.webdriver.common.by import By

    held = _paused_long_job(daemon, "held")
    with daemon.client() as c:
        behind = int(c.post("/api/v1/jobs", params={"accept_uncalibrated": "true"},
                            json={"plan": {**PLAN, "specimen": "behind"}}).json()["id"])
    try:
        wait = open_live(browser, daemon, 120)
        row = f"#jobs tr[data-id='{behind}'] td.state-queued"
        wait.until(lambda d: f"waits for job {held} (paused): resume or abort it" in
                   str(d.execute_script(
                       "return document.querySelector(arguments[0])?.textContent", row)))
        # The API says it in the same words (the page shows the daemon's).
        with daemon.client() as c:
            assert c.get(f"/api/v1/jobs/{behind}").json()["waiting"] == (
                f"waits for job {held} (paused): resume or abort it")
    finally:
        with daemon.client() as c:
            c.post(f"/api/v1/jobs/{held}/abort")
            wait_state(c, behind, ENDED, timeout=300)
    # Nothing holds the rig now: no row says it waits.
    wait.until(lambda d: "waits for job" not in d.find_element(By.ID, "jobs").text)


def test_a_paused_jobs_eta_is_the_time_once_it_runs_again_not_time_left(
    daemon: Daemon, browser: Any, no_export_fits: None  # noqa: F811
) -> None:
    """A paused job's ETA cell read "≈ 29 s left in all (est.)", as if the time ran out while
    it stood still; it now says the job is paused and the time is from when it runs again."""
    import time

    with daemon.client() as c:
        job = int(c.post("/api/v1/jobs", params={"accept_uncalibrated": "true"}, json={
            "plan": {**PLAN, "specimen": "paused eta", "rotations": 400}}).json()["id"])
        deadline = time.monotonic() + 120
        while c.get(f"/api/v1/jobs/{job}").json()["done_angles"] < 3:  # it has an ETA
            assert time.monotonic() < deadline, "the long scan did not measure"
            time.sleep(0.05)
        assert c.post(f"/api/v1/jobs/{job}/pause").status_code == 200
        while c.get(f"/api/v1/jobs/{job}").json()["state"] != "paused":
            assert time.monotonic() < deadline, "the long scan did not pause"
            time.sleep(0.05)
    try:
        wait = open_live(browser, daemon, 120)

        def eta_text(d: Any) -> str:
            d.execute_script(
                "document.querySelector(`#jobs tr[data-id='${arguments[0]}']`)?.click()", job)
            return str(d.execute_script(
                "return document.querySelector(`#jobs tr[data-id='${arguments[0]}'] td.eta`)"
                "?.textContent ?? ''", job))

        # The text the wait saw (a second read raced a redraw once in a full run).
        text = wait.until(lambda d: t if "in all" in (t := eta_text(d)) else None)
        assert text.startswith("paused: ≈ ") and "once it runs again" in text, text
        assert "left" not in text, text
    finally:
        with daemon.client() as c:
            c.post(f"/api/v1/jobs/{job}/abort")
            wait_state(c, job, ENDED, timeout=120)



_WATCH_ETA = """
const row = document.querySelector(`#jobs tr[data-id='${arguments[0]}']`);
const cell = row.querySelector('td.eta');
window.etaSeen = [cell.textContent];
new MutationObserver(() => window.etaSeen.push(cell.textContent))
  .observe(cell, {childList: true, characterData: true, subtree: true});
"""


def test_clicking_between_rows_keeps_the_running_jobs_eta(
    daemon: Daemon, browser: Any, no_export_fits: None  # noqa: F811
) -> None:
    """Clicking the running job's row blanked its ETA until the next poll (up to a second:
    the page dropped the detail it already had for the job holding the rig), and clicking
    away blanked it the same way. Every text the cell shows from each click on is an ETA."""
    import time

    with daemon.client() as c:
        running = int(c.post("/api/v1/jobs", params={"accept_uncalibrated": "true"}, json={
            "plan": {**PLAN, "specimen": "long eta", "rotations": 400}}).json()["id"])
        queued = int(c.post("/api/v1/jobs", params={"accept_uncalibrated": "true"}, json={
            "plan": {**PLAN, "specimen": "behind it"}}).json()["id"])
        deadline = time.monotonic() + 120
        while c.get(f"/api/v1/jobs/{running}").json()["done_angles"] < 3:  # it has an ETA
            assert time.monotonic() < deadline, "the long scan did not measure"
            time.sleep(0.05)
    try:
        wait = open_live(browser, daemon, 120)

        def eta_of(job: int) -> str:
            return str(browser.execute_script(
                "return document.querySelector(`#jobs tr[data-id='${arguments[0]}'] td.eta`)"
                "?.textContent ?? ''", job))

        def click(job: int) -> None:
            browser.execute_script(
                "document.querySelector(`#jobs tr[data-id='${arguments[0]}']`).click()", job)

        for target in (queued, running, queued):
            # The running job's row has its ETA (polled as the selected or the active job)...
            wait.until(lambda d: "left in all" in eta_of(running))
            browser.execute_script(_WATCH_ETA, running)
            click(target)
            wait.until(lambda d, t=target: d.execute_script(
                "return document.querySelector(`#jobs tr.selected`)?.dataset.id") == str(t))
            time.sleep(1.5)  # past the next poll of both details
            # ... and keeps it through the click: no empty moment.
            seen = browser.execute_script("return window.etaSeen")
            assert all("left in all" in t for t in seen), (target, seen)
    finally:
        with daemon.client() as c:
            for job in (queued, running):
                c.post(f"/api/v1/jobs/{job}/abort")
            for job in (queued, running):
                wait_state(c, job, ENDED, timeout=120)


def test_a_halted_queue_says_so_on_the_queued_row_and_is_released_from_the_page(
    daemon: Daemon, browser: Any, no_export_fits: None  # noqa: F811
) -> None:
    """After an emergency halt the queue is held: a queued job's row said only "queued", and
    nothing on the page could release it (the stage chip said "queue held", the API alone
    released). The row now says why (the API's ``waiting``), and "release queue" lets it run.
    The halt itself is the page's too (it had none: the CLI or the API alone halted)."""

    from selenium.webdriver.common.by import By

    wait = open_live(browser, daemon, 120)
    click_when_steady(wait, "#halt-rig")
    with daemon.client() as c:
        deadline = time.monotonic() + 60
        while "emergency halt" not in str(c.get("/api/v1/rig").json()["queue_held"]):
            assert time.monotonic() < deadline, "the page's halt did not hold the queue"
            time.sleep(0.1)
        job = int(c.post("/api/v1/jobs", params={"accept_uncalibrated": "true"},
                         json={"plan": {**PLAN, "specimen": "after halt"}}).json()["id"])
    try:
        row = f"#jobs tr[data-id='{job}'] td.state-queued"
        wait.until(lambda d: "the queue is held (emergency halt)" in str(d.execute_script(
            "return document.querySelector(arguments[0])?.textContent", row)))
        with daemon.client() as c:
            waiting = c.get(f"/api/v1/jobs/{job}").json()["waiting"]
        assert waiting in browser.execute_script(
            "return document.querySelector(arguments[0]).textContent", row)
        click_when_steady(wait, "#release-queue")
        wait.until(lambda d: not d.find_element(By.ID, "release-queue").is_displayed())
        wait.until(lambda d: d.execute_script(
            f"return document.querySelector('#jobs tr[data-id=\"{job}\"]')?.dataset.state")
            == "completed")
        assert "queue held" not in browser.find_element(By.ID, "stage-chip").text
    finally:
        with daemon.client() as c:
            c.post("/api/v1/rig/release")
            wait_state(c, job, ENDED, timeout=300)


def test_aborting_a_job_asks_first_and_says_what_it_ends(
    daemon: Daemon, browser: Any, no_export_fits: None  # noqa: F811
) -> None:
    """"abort" ended a job for good at one click, next to "pause": the page now asks, saying
    that it writes no result and cannot be resumed; dismissed, the job stays as it was."""
    import time

    job = _paused_long_job(daemon, "to abort")

    def still_paused() -> None:
        with daemon.client() as c:
            assert c.get(f"/api/v1/jobs/{job}").json()["state"] == "paused"

    try:
        wait = open_live(browser, daemon, 120)
        _asked_then_confirmed(wait, f"#jobs tr[data-id='{job}'] button[data-action='abort']",
                              (f"Abort job {job} (to abort)?", "writes no result",
                               "cannot be resumed"), still_paused)
        with daemon.client() as c:
            deadline = time.monotonic() + 120
            while c.get(f"/api/v1/jobs/{job}").json()["state"] != "aborted":
                assert time.monotonic() < deadline, "the job was not aborted"
                time.sleep(0.1)
    finally:
        with daemon.client() as c:
            if c.get(f"/api/v1/jobs/{job}").json()["state"] != "aborted":
                c.post(f"/api/v1/jobs/{job}/abort")


def _settled_caption(d: Any, job: int, needle: str) -> str | bool:
    """The colour caption once job ``job`` is shown and its caption holds ``needle``: the
    same snapshot for the wait and the assertions after it (False until then)."""
    if not _text(d, "result-job").startswith(f"job {job} "):
        return False
    caption = _text(d, "colour-caption")
    return caption if needle in caption else False


def test_an_uncalibrated_result_against_a_standard_says_why_there_is_no_delta_e(
    daemon: Daemon, browser: Any, finished_job: int,  # noqa: F811
) -> None:
    """A stored standard chosen for an uncalibrated result (values in sensor units) showed
    the channel values and no ΔE00 column, saying nothing about the comparison asked for.
    The caption now says there is none, why, and what to do (the API's ``no_colour``)."""
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import Select

    from gonio.brdf.colour.chart import ColourMatrix
    from gonio.brdf.colour.report import colour_report
    from tests.unit.cli.test_colour_command import _lambert, _matrix

    job = finished_job
    # A lab's master, measured elsewhere with colour: a CIELAB colour CSV.
    master = colour_report(_lambert(), ColourMatrix.from_dict(_matrix()), None, ["MA98"])
    stored = daemon.data_dir / "standards" / "lab master.csv"
    try:
        with daemon.client() as c:
            put = c.put("/api/v1/colour-standards/lab master", content=master.csv(),
                        headers={"Content-Type": "text/csv"})
            assert put.status_code in (200, 201), put.text
            why = c.get(f"/api/v1/jobs/{job}/colour").json()["no_colour"]
        wait = open_live(browser, daemon, 120)
        click_when_steady(wait, f'#jobs tr[data-id="{job}"]')
        # The caption checked is the one the wait saw: the page may recompute the colour
        # (a refresh shows "Computing colour…" for a moment) between two separate reads.
        caption = wait.until(lambda d: _settled_caption(d, job, "uncalibrated sensor RGB"))
        # Why there is no CIELAB is said once, in the daemon's words (the caption said "no
        # CIELAB" and then the API's no_colour said it again); its values are sensor units,
        # not reflectance factors.
        assert caption.lower().count("no cielab") == 1, caption
        assert f"values per channel in sensor units (3 channels). {why}." in caption, caption
        assert "reflectance factors" not in caption, caption
        wait.until(lambda d: "lab master" in [o.get_attribute("value") for o in
                                              d.find_elements(By.CSS_SELECTOR,
                                                              "#colour-standard option")])
        Select(browser.find_element(By.ID, "colour-standard")).select_by_value("lab master")
        caption = wait.until(lambda d: _settled_caption(
            d, job, "No ΔE00 against standard lab master"))
        assert f"No ΔE00 against standard lab master: {why}." in caption, caption
        assert caption.lower().count("no cielab") == 1, caption
        assert "calibrate the rig on the white reference" in caption, caption
        head = [th.text for th in browser.find_elements(By.CSS_SELECTOR,
                                                        "#colour-table thead th")]
        assert "ΔE00" not in head
        Select(browser.find_element(By.ID, "colour-standard")).select_by_value("")
    finally:
        stored.unlink(missing_ok=True)
