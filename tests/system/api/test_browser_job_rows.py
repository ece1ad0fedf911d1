"""The lab page's queue and panels as a lab day met them (a reviewer's findings, in headless
Chromium against a real daemon):

* a removed job stayed in the result and readings panels, its exports offered, and every
  control answered "no job with id N";
* a finished row kept its "reconstructing ... taking longer than estimated" ETA;
* rows could not be opened from the keyboard;
* the page never said which calibration is in effect until a scan was refused for it;
* a polar incidence out of range was refused in the API's words ("theta_i: Input should
  be ...").

Expected values come from the daemon's API (GET /jobs, GET /calibration), not the page."""

from __future__ import annotations

import time
from typing import Any

import pytest

from tests.system.api.conftest import Daemon, export_fits_off
from tests.system.api.test_browser import (  # noqa: F401 (the fixture)
    _calibrate,
    _severe,
    browser,
    open_live,
)

pytestmark = [pytest.mark.system, pytest.mark.timeout(300)]

FAST = {"exposure_s": 0.005, "light_settle_s": 0.0}


def _scan(c: Any, name: str) -> int:
    r = c.post("/api/v1/jobs", json={"plan": {"kind": "uniform", "rotations": 2,
                                              "exposure": FAST, "specimen": name}})
    assert r.status_code == 201, r.text
    return int(r.json()["id"])


def _until(what: str, cond: Any, timeout_s: float = 120.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not cond():
        assert time.monotonic() < deadline, what
        time.sleep(0.1)


def test_rows_panels_and_calibration_line_tell_the_truth(
        daemon: Daemon, browser: Any,  # noqa: F811 (the fixture)
) -> None:
    from selenium.webdriver.common.by import By
    from selenium.webdriver.common.keys import Keys

    _calibrate(daemon)
    wait = open_live(browser, daemon, 120)
    text = lambda css: str(browser.find_element(By.CSS_SELECTOR, css).text)  # noqa: E731

    # The calibration in effect, as the daemon reports it, under the form.
    with daemon.client() as c:
        cal = c.get("/api/v1/calibration").json()
    assert cal["pairs"], cal
    wait.until(lambda d: text("#calibration-line").startswith("Calibration in effect:"))
    line = text("#calibration-line")
    assert cal["source"] in line and f"at exposure {cal['exposure_s']} s" in line, line

    with export_fits_off(daemon), daemon.client() as c:
        first, second = _scan(c, "row one"), _scan(c, "row two")
        _until("both scans complete", lambda: all(
            c.get(f"/api/v1/jobs/{j}").json()["state"] == "completed" for j in (first, second)))
        # Every finished row's ETA is empty once the list says so (it kept the detail polled
        # while the job was reconstructing).
        wait.until(lambda d: all(
            td.text == "" for td in d.find_elements(
                By.CSS_SELECTOR, "#jobs tr[data-state='completed'] td.eta")))

        # The first row opened from the keyboard: focus it, Enter.
        browser.execute_script(
            f"document.querySelector('#jobs tr[data-id=\"{first}\"]').focus()")
        browser.switch_to.active_element.send_keys(Keys.ENTER)
        wait.until(lambda d: text("#result-job") == f"job {first} (completed)")

        # A polar incidence out of range: the panel's words, not the API parameter's.
        ti = browser.find_element(By.ID, "polar-ti")
        ti.clear()
        ti.send_keys("95")
        browser.execute_script(
            "document.getElementById('polar-ti').dispatchEvent(new Event('change'))")
        wait.until(lambda d: text("#message").startswith("Polar plots"))
        said = text("#message")
        assert said.startswith("Polar plots: enter the incidence θi as a number from 0 to 85"), \
            said
        ti.clear()
        ti.send_keys("30")

        # The shown job removed behind the page's back (another tab, `gonio jobs remove`):
        # the panels leave it, and its row goes.
        assert c.delete(f"/api/v1/jobs/{first}").status_code == 204
        wait.until(lambda d: not d.find_elements(By.CSS_SELECTOR,
                                                 f"#jobs tr[data-id='{first}']"))
        wait.until(lambda d: text("#result-job") != f"job {first} (completed)")
        assert f"job {first} " not in text("#live-job"), text("#live-job")
    assert [e for e in _severe(browser) if "status of 4" not in e["message"]] == []
