"""A new lab user's first hour on the lab page, in headless Chromium: the surprises it met
(a queued scan taking the running one off the screen, a plan's time without its
reconstruction, a refused key's stale queue), each checked against the API's own answer."""

from __future__ import annotations

import re
import time
from typing import Any

import pytest

from tests.system.api.conftest import Daemon, export_fits_off
from tests.system.api.test_browser import (  # noqa: F401 (fixture)
    browser,
    click_when_steady,
    open_live,
)

pytestmark = [pytest.mark.system, pytest.mark.timeout(300)]

LONG = {"kind": "uniform", "specimen": "long felt", "rotations": 400,
        "exposure": {"exposure_s": 0.005}}
"""A scan that measures for far longer than a test looks at it (aborted at the end)."""


def _wait_state(daemon: Daemon, job: int, states: set[str], timeout_s: float = 120) -> None:
    with daemon.client() as c:
        deadline = time.monotonic() + timeout_s
        while c.get(f"/api/v1/jobs/{job}").json()["state"] not in states:
            assert time.monotonic() < deadline, f"job {job} never reached {states}"
            time.sleep(0.1)


def _eta(driver: Any, job: int) -> str:
    """The ETA cell of ``job``'s row as drawn now (read in one step: the rows are redrawn as
    events arrive)."""
    return str(driver.execute_script(
        "const c = document.querySelector(`#jobs tr[data-id=\"${arguments[0]}\"] td.eta`);"
        "return c ? c.textContent : '';", job))


def _abort_all(daemon: Daemon) -> None:
    """Cancel the queued jobs, then abort the rest, until none is left (a queued job may start
    between the list and its cancel)."""
    live = ("queued", "running", "paused", "suspended", "reconstructing")
    with daemon.client() as c:
        deadline = time.monotonic() + 60
        while True:
            listed = [j for j in c.get("/api/v1/jobs").json() if j["state"] in live]
            if not listed:
                return
            assert time.monotonic() < deadline, f"jobs did not stop: {listed}"
            for j in sorted(listed, key=lambda j: j["state"] != "queued"):
                action = "cancel" if j["state"] == "queued" else "abort"
                c.post(f"/api/v1/jobs/{j['id']}/{action}")
            time.sleep(0.2)


def test_a_scan_queued_behind_a_running_one_leaves_the_running_one_on_screen(
        daemon: Daemon, browser: Any) -> None:  # noqa: F811 (the fixture)
    from selenium.webdriver.common.by import By

    wait = open_live(browser, daemon, 120)
    with daemon.client() as c:
        running = c.post("/api/v1/jobs", params={"accept_uncalibrated": "true"},
                         json={"plan": LONG}).json()["id"]
    try:
        _wait_state(daemon, running, {"running"})
        with daemon.client() as c:
            wait.until(lambda _d: c.get(f"/api/v1/jobs/{running}").json()["done_angles"] >= 2)
        form = browser.find_element(By.ID, "scan-form")
        name = form.find_element(By.NAME, "specimen")
        name.clear()
        name.send_keys("felt B")
        # At the running scan's exposure: a calibration this module's colour test may have
        # made runs at it, and Start is refused at another (the form's default 0.01 s).
        exposure = form.find_element(By.NAME, "exposure_s")
        exposure.clear()
        exposure.send_keys("0.005")  # LONG's
        click_when_steady(wait, "#start-scan")
        wait.until(lambda d: "queued" in d.find_element(By.ID, "dry-run-result").text)
        with daemon.client() as c:
            listed = c.get("/api/v1/jobs").json()
        queued = next(j for j in listed if j["specimen"] == "felt B")
        assert queued["state"] == "queued", queued
        # The readings and result panels stay on the job that measures (the API's own list
        # says which), with its readings coming in; the new job's row is only listed.
        wait.until(lambda d: d.find_element(By.ID, "live-job").text.startswith(f"job {running} "))
        assert browser.find_element(By.ID, "result-job").text.startswith(f"job {running}")
        with daemon.client() as c:
            stored = len(c.get(f"/api/v1/jobs/{running}/readings").json())
        assert stored > 0
        wait.until(lambda d: int(d.find_element(By.ID, "live-job").text.split("·")[1].split()[0])
                   > 0)
        # The running job's ETA stays in its row.
        wait.until(lambda d: "left" in _eta(d, running))
        note = browser.find_element(By.ID, "dry-run-result").text
        # Nothing that turns false as the queue moves (it said "starts after job 4" while
        # other jobs went first): the row says when it starts.
        assert f"Job {queued['id']} queued: its row says when it starts" in note, note
        assert f"showing job {running} (" in note and "starts after" not in note, note
    finally:
        _abort_all(daemon)


def test_check_plan_says_its_time_is_the_measuring_and_how_long_the_finishing_takes(
        daemon: Daemon, browser: Any) -> None:  # noqa: F811 (the fixture)
    """docs/api.md: the dry run's estimated_s is motion + settle + exposure, the measuring
    alone. The note read "about 7.6 s" for a default scan that took 28 s to its result (20 s
    of it the reconstruction), with nothing saying a reconstruction follows."""
    from selenium.webdriver.common.by import By

    wait = open_live(browser, daemon, 60)
    with daemon.client() as c:
        plan = {"kind": "uniform", "specimen": "unnamed", "rotations": 8, "span_deg": 180,
                "exposure": {"exposure_s": 0.01, "averages": 1}}
        r = c.post("/api/v1/jobs/dry-run", json={"plan": plan}).json()
    assert r["estimated_s"] == pytest.approx(r["motion_s"] + r["settle_s"] + r["exposure_s"])
    click_when_steady(wait, "#dry-run")
    wait.until(lambda d: "readings at" in d.find_element(By.ID, "dry-run-result").text)
    note = browser.find_element(By.ID, "dry-run-result").text
    # ... and then the finishing, as the daemon's dry run times it (the last scans' finishing
    # on this store, or the default's), with what that rests on.
    assert r["finishing_s"] is not None and r["finishing_source"], r
    assert "That is the measuring; then about" in note, note
    assert f"to reconstruct and fit the exports ({r['finishing_source']})." in note, note


def test_a_refused_key_stops_the_polls_and_says_the_queue_is_as_last_read(
        daemon: Daemon, browser: Any) -> None:  # noqa: F811 (the fixture)
    """After `gonio serve --sim --throwaway` restarted (a new key, none of the old jobs), the
    page went on showing the old daemon's running job with "≈ 32 s left" and asked the new
    daemon for it once a second with the refused key: a 403 line a second in its console."""
    from selenium.webdriver.common.by import By

    with daemon.client() as c:
        running = c.post("/api/v1/jobs", params={"accept_uncalibrated": "true"},
                         json={"plan": LONG}).json()["id"]
    try:
        _wait_state(daemon, running, {"running"})
        wait = open_live(browser, daemon, 120)
        click_when_steady(wait, f'#jobs tr[data-id="{running}"] td')
        wait.until(lambda d: "left" in _eta(d, running))
        # The key this tab will send from now on is not one of the daemon's: it refuses it,
        # reads included (docs/api.md, Keys and access).
        with daemon.client(key="not-a-key-of-this-daemon") as c:
            assert c.get(f"/api/v1/jobs/{running}").status_code == 403
        browser.execute_script("sessionStorage.setItem('gonio.apiKey', arguments[0]);"
                               "window.__asked = [];"
                               "const f = window.fetch;"
                               "window.fetch = (u, i) => { window.__asked.push(String(u));"
                               " return f(u, i); };", "not-a-key-of-this-daemon")
        wait.until(lambda d: d.find_element(By.ID, "key-prompt").is_displayed())
        browser.execute_script("window.__asked = [];")
        time.sleep(4)
        asked = browser.execute_script("return window.__asked")
        polls = [u for u in asked if u.endswith(f"/jobs/{running}")]
        assert polls == [], asked
        assert browser.find_element(By.ID, "jobs-stale").is_displayed()
        assert "as the page last read them" in browser.find_element(By.ID, "jobs-stale").text
        assert _eta(browser, running) == "", _eta(browser, running)
        # A key that works brings the queue back, and its ETA.
        field = browser.find_element(By.ID, "key-input")
        field.clear()
        field.send_keys(daemon.key)
        click_when_steady(wait, "#key-form button[type=submit]")
        wait.until(lambda d: not d.find_element(By.ID, "jobs-stale").is_displayed())
        wait.until(lambda d: "left" in _eta(d, running))
    finally:
        _abort_all(daemon)


def test_the_running_job_keeps_its_eta_while_another_row_is_selected(
        daemon: Daemon, browser: Any) -> None:  # noqa: F811 (the fixture)
    """The ETA column showed only the selected job's: a click on a queued (or finished) job
    left the measuring one's row blank, the one time the lab plans the day around."""
    from selenium.webdriver.common.by import By

    with daemon.client() as c:
        running = c.post("/api/v1/jobs", params={"accept_uncalibrated": "true"},
                         json={"plan": LONG}).json()["id"]
        waiting = c.post("/api/v1/jobs", params={"accept_uncalibrated": "true"},
                         json={"plan": {**LONG, "specimen": "next felt"}}).json()["id"]
    try:
        _wait_state(daemon, running, {"running"})
        wait = open_live(browser, daemon, 120)
        click_when_steady(wait, f'#jobs tr[data-id="{waiting}"] td')
        wait.until(lambda d: d.find_element(By.ID, "result-job").text.startswith(f"job {waiting}"))
        # The daemon has a time left for the running job (its own answer), and the page
        # shows it in that job's row although another row is selected.
        with daemon.client() as c:
            detail = c.get(f"/api/v1/jobs/{running}").json()
        assert detail["state"] == "running" and detail["time_left_s"] is not None, detail
        wait.until(lambda d: "left in all" in _eta(d, running))
        # The queued row says when it starts (the running job's time left, GET
        # /api/v1/jobs' starts_in_s), never the running job's own time.
        assert _eta(browser, waiting).startswith("starts in about "), _eta(browser, waiting)
    finally:
        _abort_all(daemon)


def test_the_colour_caption_of_sensor_rgb_says_what_is_uncalibrated_and_what_source_means(
        daemon: Daemon, browser: Any) -> None:  # noqa: F811 (the fixture)
    """A calibrated scan (values in 1/sr) on RGB sensors without a colour calibration: the
    colour caption began "uncalibrated sensor RGB" under a headline saying "Calibrated", and
    its table's "source" column ("table" on every row) was explained only for CIELAB."""
    from selenium.webdriver.common.by import By

    from tests.system.api.test_browser import _calibrate

    _calibrate(daemon)
    with export_fits_off(daemon), daemon.client() as c:
        job = c.post("/api/v1/jobs", json={"plan": {
            "kind": "uniform", "specimen": "rgb felt", "rotations": 8,
            "exposure": {"exposure_s": 0.005}}}).json()["id"]
        _wait_state(daemon, job, {"completed"}, 180)
        colour = c.get(f"/api/v1/jobs/{job}/colour").json()["colour"]
    assert colour["space"] == "uncalibrated sensor RGB", colour["space"]
    read = sum(bool(m) for m in colour.get("measured") or [])
    wait = open_live(browser, daemon, 120)
    click_when_steady(wait, f'#jobs tr[data-id="{job}"] td')
    wait.until(lambda d: "reflectance factors per channel" in
               d.find_element(By.ID, "colour-caption").text)
    caption = browser.find_element(By.ID, "colour-caption").text
    assert "Uncalibrated here is the colour" in caption, caption
    # Why there is no CIELAB: once, in the daemon's words (the API's no_colour).
    assert caption.lower().count("no cielab") == 1, caption
    if read:
        assert f'Source "pair": {read} of {len(colour["measured"])} geometries' in caption, caption
    else:
        assert 'Source "table": every geometry read from the reconstructed table' in caption, \
            caption


def test_a_slow_rendering_and_export_count_their_seconds(daemon: Daemon, browser: Any) -> None:  # noqa: F811
    """The rendering's caption said "a few seconds the first time" for the 39 s a rendering
    took beside a reconstruction, and an export said "exporting…" for a minute: both count
    the seconds so far instead. The daemon's answers are held back 4 s in the page (a
    wrapped fetch), timed by the test's own clock."""
    from selenium.webdriver.common.by import By

    with export_fits_off(daemon), daemon.client() as c:
        job = c.post("/api/v1/jobs", params={"accept_uncalibrated": "true"}, json={"plan": {
            "kind": "uniform", "specimen": "slow picture", "rotations": 4,
            "exposure": {"exposure_s": 0.005}}}).json()["id"]
        _wait_state(daemon, job, {"completed"}, 180)
    # The wrapper goes in before the page's own scripts run: the page opens on the newest
    # job, this one, and asks for its rendering while it loads, before a wrapper installed
    # after the load could catch that request.
    hold_back = browser.execute_cdp_cmd("Page.addScriptToEvaluateOnNewDocument", {"source": (
        "const f = window.fetch;"
        "window.fetch = async (u, i) => { if (/[/]render[.]png|[/]export[?]/.test(String(u)))"
        " await new Promise((r) => setTimeout(r, 4000)); return f(u, i); };")})
    try:
        wait = open_live(browser, daemon, 120)
    finally:  # the pages of later tests load without it
        browser.execute_cdp_cmd("Page.removeScriptToEvaluateOnNewDocument", hold_back)
    click_when_steady(wait, f'#jobs tr[data-id="{job}"] td')
    wait.until(lambda d: d.find_element(By.ID, "result-job").text.startswith(f"job {job}"))
    # The rendering is asked for once the job's metrics and preview are in (app.js
    # showResult); its seconds count from then.
    wait.until(lambda d: "s so far" in d.find_element(By.ID, "render-caption").text)
    started = time.monotonic()
    time.sleep(2.6)
    caption = browser.find_element(By.ID, "render-caption").text
    elapsed = time.monotonic() - started
    m = re.search(r"Rendering… (\d+) s so far", caption)
    assert m, caption
    assert 1 <= int(m.group(1)) <= round(elapsed) + 1, (caption, elapsed)
    # Once the picture arrives the caption says what it shows.
    wait.until(lambda d: "Click to open full size" in d.find_element(By.ID, "render-caption").text)
    # An export, as slow, counts its seconds too, and says what it saved.
    from selenium.webdriver.support.ui import Select

    Select(browser.find_element(By.ID, "export-format")).select_by_value("table")
    click_when_steady(wait, "#export-button")
    started = time.monotonic()
    time.sleep(2.6)
    state = browser.find_element(By.ID, "export-state").text
    elapsed = time.monotonic() - started
    m = re.search(r"exporting… (\d+) s so far", state)
    assert m, state
    assert 1 <= int(m.group(1)) <= round(elapsed) + 1, (state, elapsed)
    wait.until(lambda d: d.find_element(By.ID, "export-state").text.startswith("saved "))
