"""The lab page's queue table in headless Chromium against the real daemon on the simulated rig
(tests/system/api/conftest.py, as tests/system/api/test_browser.py): a click on a row's button
while events redraw the table; a move that needs the user's acceptance."""

from __future__ import annotations

import time
from typing import Any

import pytest

from tests.system.api.conftest import Daemon
from tests.system.api.test_browser import (  # noqa: F401 (fixture)
    browser,
    click_when_steady,
    open_live,
)
from tests.system.api.test_browser_lab_day import (  # noqa: F401 (fixture)
    PLAN,
    _row_ids,
    calibrated_elsewhere,
)
from tests.system.api.test_scan_flow import ENDED, wait_state

pytestmark = [pytest.mark.system, pytest.mark.timeout(600)]


def _state(daemon: Daemon, job: int) -> str:
    with daemon.client() as c:
        return str(c.get(f"/api/v1/jobs/{job}").json()["state"])


def _progress(browser: Any, job: int) -> str:  # noqa: F811 (the fixture's name)
    return str(browser.execute_script(
        "return document.querySelector(`#jobs tr[data-id='${arguments[0]}'] td.progress`)"
        "?.textContent ?? ''", job))


def test_a_click_on_a_rows_button_acts_though_events_redraw_the_table_meanwhile(
    daemon: Daemon, browser: Any, no_export_fits: None  # noqa: F811
) -> None:
    """Every event rebuilt the whole queue table, so a button pressed before a redraw and
    released after it was a detached one: the click was lost (no pause, no abort question),
    for a lab user as for the browser tests beside a busy CPU. Here the mouse is pressed on a
    row's button, the table is redrawn (readings arrive, a job is queued), and only then is
    the mouse released: the click acts."""
    from selenium.common.exceptions import TimeoutException
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support import expected_conditions as ec

    with daemon.client() as c:
        job = int(c.post("/api/v1/jobs", params={"accept_uncalibrated": "true"}, json={
            "plan": {**PLAN, "specimen": "clicked", "rotations": 400}}).json()["id"])
    behind = None
    try:
        wait = open_live(browser, daemon, 120)
        row = f"#jobs tr[data-id='{job}']"
        # Measuring, with its ETA shown (the row's layout as it stays while the job runs).
        wait.until(lambda d: _progress(d, job).startswith(" ") and
                   int(_progress(d, job).split("/")[0]) >= 1 and "in all" in str(
                       d.execute_script("return document.querySelector(arguments[0])"
                                        "?.textContent", f"{row} td.eta")))
        # Where each press, release and click landed: said if a click is lost.
        browser.execute_script(
            "window.__landed = [];"
            "for (const t of ['mousedown', 'mouseup', 'click']) document.addEventListener(t,"
            " (e) => window.__landed.push(`${t} on ${e.target.tagName}.${e.target.dataset.action"
            " ?? ''} ${e.target.isConnected ? '' : '(detached)'}`), true);")
        # Pressed on "pause" while the job measures; released once a reading has redrawn the
        # row's progress (an event, a list refresh, a redraw).
        pause = browser.find_element(By.CSS_SELECTOR, f"{row} button[data-action='pause']")
        before = _progress(browser, job)
        ActionChains(browser).move_to_element(pause).click_and_hold().perform()
        wait.until(lambda d: _progress(d, job) != before)
        ActionChains(browser).release().perform()
        deadline = time.monotonic() + 120
        while _state(daemon, job) != "paused":
            landed = browser.execute_script("return window.__landed")
            assert time.monotonic() < deadline, f"the click on pause was lost: {landed}"
            time.sleep(0.1)
        # Pressed on "abort" of the paused job; released once the job has been resumed
        # elsewhere (its row's state and buttons redrawn: resume became pause, abort stays)
        # and a job queued behind it has been drawn (a row added): the question comes.
        wait.until(lambda d: d.find_elements(
            By.CSS_SELECTOR, f"{row}[data-state='paused'] button[data-action='resume']"))
        abort = browser.find_element(By.CSS_SELECTOR, f"{row} button[data-action='abort']")
        ActionChains(browser).move_to_element(abort).click_and_hold().perform()
        with daemon.client() as c:
            assert c.post(f"/api/v1/jobs/{job}/resume").status_code == 200
            behind = int(c.post("/api/v1/jobs", params={"accept_uncalibrated": "true"},
                                json={"plan": {**PLAN, "specimen": "behind"}}).json()["id"])
        wait.until(lambda d: str(behind) in _row_ids(d) and d.find_elements(
            By.CSS_SELECTOR, f"{row}[data-state='running'] button[data-action='pause']"))
        ActionChains(browser).release().perform()
        try:
            question = wait.until(ec.alert_is_present())
        except TimeoutException:
            landed = browser.execute_script("return window.__landed")
            raise AssertionError(f"the click on abort was lost: {landed}") from None
        assert f"Abort job {job} (clicked)?" in question.text, question.text
        question.accept()
        wait.until(lambda d: _state(daemon, job) == "aborted")
    finally:
        with daemon.client() as c:
            if _state(daemon, job) not in ENDED:
                c.post(f"/api/v1/jobs/{job}/abort")
            if behind is not None:
                wait_state(c, behind, ENDED, timeout=300)


def test_moving_a_scan_ahead_of_a_queued_calibration_asks_and_sends_the_acceptance(
    daemon: Daemon, browser: Any, calibrated_elsewhere: None  # noqa: F811
) -> None:
    """A scan queued behind a calibration (on a rig calibrated elsewhere) moved up with ▲ was
    refused with a 409 naming ``accept_uncalibrated``, a field the page could not send: the
    row could not move. The page now asks, saying the scan would run before the calibration,
    uncalibrated; dismissed, the order stays; accepted, it resends with the acceptance."""
    from selenium.webdriver.support import expected_conditions as ec

    cal_plan = {"kind": "calibration", "reference_albedo": 0.99, "rotations": 2,
                "exposure": {"exposure_s": 0.005}}
    with daemon.client() as c:
        assert c.post("/api/v1/rig/halt").status_code == 200  # all stay queued
        cal = int(c.post("/api/v1/jobs", json={"plan": cal_plan}).json()["id"])
        r = c.post("/api/v1/jobs", json={"plan": {**PLAN, "specimen": "eager"}})
        assert r.status_code == 201, r.text  # behind the calibration: not asked
        scan = int(r.json()["id"])
    try:
        wait = open_live(browser, daemon, 120)
        wait.until(lambda d: _row_ids(d)[-2:] == [str(cal), str(scan)])
        up = f"#jobs tr[data-id='{scan}'] button[data-action='up']"
        click_when_steady(wait, up)
        question = wait.until(ec.alert_is_present())
        text = question.text
        for phrase in (f"Job {scan} would then run before calibration job {cal}, uncalibrated",
                       "the scan would run before the calibration", "sensor units",
                       "Move it all the same?"):
            assert phrase in text, text
        question.dismiss()
        with daemon.client() as c:
            assert c.get(f"/api/v1/jobs/{scan}").json()["queue_position"] > \
                c.get(f"/api/v1/jobs/{cal}").json()["queue_position"]
        assert _row_ids(browser)[-2:] == [str(cal), str(scan)]
        click_when_steady(wait, up)
        wait.until(ec.alert_is_present()).accept()
        wait.until(lambda d: _row_ids(d)[-2:] == [str(scan), str(cal)])
        with daemon.client() as c:
            assert c.get(f"/api/v1/jobs/{scan}").json()["queue_position"] < \
                c.get(f"/api/v1/jobs/{cal}").json()["queue_position"]
        assert not browser.find_element("id", "message").is_displayed()
    finally:
        with daemon.client() as c:
            for job in (scan, cal):
                c.post(f"/api/v1/jobs/{job}/cancel")
            assert c.post("/api/v1/rig/release").status_code == 200


def test_the_scan_form_sends_a_priority_and_refuses_one_that_is_not_a_whole_number(
    daemon: Daemon, browser: Any  # noqa: F811
) -> None:
    """The API took a priority (``POST /api/v1/jobs``, -1000..1000, higher starts sooner) the
    scan form had no field for: a lab could only move a job after queueing it. The form now
    has one, says what higher means, sends it with the job, and the queue shows it; a number
    that is not a whole one is refused at the field and nothing is sent."""
    from selenium.webdriver.common.by import By

    with daemon.client() as c:
        assert c.post("/api/v1/rig/halt").status_code == 200  # the new job stays queued
    job = None
    try:
        wait = open_live(browser, daemon, 120)
        assert "Higher priority starts sooner" in browser.find_element(
            By.ID, "priority-help").text
        form = browser.find_element(By.ID, "scan-form")
        field = form.find_element(By.NAME, "priority")
        assert field.get_attribute("value") == "0"
        specimen = form.find_element(By.NAME, "specimen")
        specimen.clear()
        specimen.send_keys("urgent")
        browser.execute_script("window.__posted = []; const f = window.fetch;"
                               "window.fetch = (u, i) => { if (i && i.method === 'POST')"
                               " window.__posted.push(String(u)); return f(u, i); };")
        for bad in ("2.5", "5000", ""):
            field.clear()
            field.send_keys(bad)
            click_when_steady(wait, "#start-scan")
            wait.until(lambda d: d.switch_to.active_element == field)
            said = browser.execute_script("return arguments[0].validationMessage", field)
            assert "whole number from -1000 to 1000" in said, (bad, said)
            assert "higher starts sooner" in said, said
            assert browser.execute_script("return window.__posted") == [], bad
        field.clear()
        field.send_keys("7")
        assert browser.execute_script("return arguments[0].validity.valid", field) is True
        click_when_steady(wait, "#start-scan")
        row = "//tbody[@id='jobs']/tr[td[2][text()='urgent']]"
        wait.until(lambda d: d.find_elements(By.XPATH, row))
        job = int(browser.find_element(By.XPATH, row).get_attribute("data-id"))
        with daemon.client() as c:
            assert c.get(f"/api/v1/jobs/{job}").json()["priority"] == 7
        wait.until(lambda d: d.find_element(
            By.CSS_SELECTOR, f"#jobs tr[data-id='{job}'] td.kind .priority").text
            == "priority 7")
        assert not browser.find_element(By.ID, "message").is_displayed(), \
            browser.find_element(By.ID, "message").text
    finally:
        with daemon.client() as c:
            if job is not None:
                c.post(f"/api/v1/jobs/{job}/cancel")
            assert c.post("/api/v1/rig/release").status_code == 200


def _eta_cell(browser: Any, job: int) -> tuple[str, str]:  # noqa: F811 (the fixture's name)
    return tuple(browser.execute_script(  # type: ignore[return-value]
        "const c = document.querySelector(`#jobs tr[data-id='${arguments[0]}'] td.eta`);"
        "return [c?.textContent ?? '', c?.title ?? ''];", job))


def test_queued_jobs_say_when_they_start_and_unknown_when_the_queue_is_held(
    daemon: Daemon, browser: Any, no_export_fits: None  # noqa: F811
) -> None:
    """The queue showed queued jobs with no idea of when they start. Each now says "starts in
    about ..." (GET /api/v1/jobs' starts_in_s: the running job's time left plus the estimated
    durations of the jobs ahead), and "start unknown" once the queue is held: no number is
    made up for a queue that does not run."""
    with daemon.client() as c:
        post = {"params": {"accept_uncalibrated": "true"}}
        holding = int(c.post("/api/v1/jobs", **post, json={  # type: ignore[arg-type]
            "plan": {**PLAN, "specimen": "holding", "rotations": 400}}).json()["id"])
        ahead = int(c.post("/api/v1/jobs", **post, json={  # type: ignore[arg-type]
            "plan": {**PLAN, "specimen": "ahead"}}).json()["id"])
        behind = int(c.post("/api/v1/jobs", **post, json={  # type: ignore[arg-type]
            "plan": {**PLAN, "specimen": "behind"}}).json()["id"])
    try:
        with daemon.client() as c:
            deadline = time.monotonic() + 120
            while c.get(f"/api/v1/jobs/{holding}").json()["time_left_s"] is None:
                assert time.monotonic() < deadline, "the running job never had a time left"
                time.sleep(0.2)
            listed = {j["id"]: j for j in c.get("/api/v1/jobs").json()}
            left = c.get(f"/api/v1/jobs/{holding}").json()["time_left_s"]
        first, second = listed[ahead], listed[behind]
        # Counted down between the two reads: the list's estimate is a little larger.
        assert left <= first["starts_in_s"] <= left + 30, (left, first)
        assert second["starts_in_s"] > first["starts_in_s"], (first, second)
        assert not first["starts_in_bound"] and not second["starts_in_bound"]
        assert first["starts_in_estimate"] == f"job {holding}'s time left"
        assert second["starts_in_estimate"] == (
            f"job {holding}'s time left plus the estimated durations of job {ahead} ahead")
        assert listed[holding]["starts_in_s"] is None
        assert listed[holding]["starts_in_estimate"] is None

        wait = open_live(browser, daemon, 120)
        for job in (ahead, behind):
            wait.until(lambda d, job=job: _eta_cell(d, job)[0].startswith("starts in about "))
        assert "time left" in _eta_cell(browser, behind)[1]
        with daemon.client() as c:
            assert c.post("/api/v1/rig/halt").status_code == 200
        for job in (ahead, behind):
            wait.until(lambda d, job=job: _eta_cell(d, job)[0] == "start unknown")
        assert _eta_cell(browser, ahead)[1].startswith("not known: the queue is held")
        with daemon.client() as c:
            for j in c.get("/api/v1/jobs", params={"state": "queued"}).json():
                assert j["starts_in_s"] is None, j
    finally:
        with daemon.client() as c:
            for job in (ahead, behind):
                c.post(f"/api/v1/jobs/{job}/cancel")
            if _state(daemon, holding) not in {*ENDED, "halted"}:
                c.post(f"/api/v1/jobs/{holding}/abort")
            assert c.post("/api/v1/rig/release").status_code == 200
