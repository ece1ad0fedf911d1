"""The lab page's result headline does not say a plain "Calibrated: values in 1/sr" for a scan
whose calibration was measured at another exposure (counts are not rescaled, so every value is
off by the ratio): it said exactly that, with the reason only as a bare key under "All
metrics". Headless Chromium against the real daemon on the simulated rig, as
tests/system/api/test_browser.py."""

from __future__ import annotations

import time
from typing import Any

import pytest

from tests.system.api.conftest import Daemon, export_fits_off
from tests.system.api.test_browser import (  # noqa: F401 (fixture)
    _calibrate,
    browser,
    open_live,
)

pytestmark = [pytest.mark.system, pytest.mark.timeout(600)]


def _text(browser: Any, element_id: str) -> str:  # noqa: F811 (the fixture's name)
    return str(browser.execute_script(
        "return document.getElementById(arguments[0])?.textContent ?? ''", element_id))


def test_the_headline_says_a_calibration_at_another_exposure_does_not_fit(
    daemon: Daemon, browser: Any  # noqa: F811
) -> None:
    _calibrate(daemon)  # at 0.005 s
    plan = {"kind": "uniform", "specimen": "felt", "rotations": 2,
            "exposure": {"exposure_s": 0.01}}
    # A scan at another exposure than the calibration is refused at submission and at its
    # start: the mismatch is made as a calibration replaced under the running scan (a file
    # edited by hand), the service seeing one at the scan's exposure until it has started.
    service = daemon.app.state.service
    assert service._calibration is None  # the calibration job's, read from the data dir
    service._calibration = service.calibration().model_copy(update={"exposure_s": 0.01})
    with export_fits_off(daemon), daemon.client() as c:
        try:
            r = c.post("/api/v1/jobs", json={"plan": plan})
            assert r.status_code == 201, r.text
            job = int(r.json()["id"])
            while c.get(f"/api/v1/jobs/{job}").json()["state"] == "queued":
                time.sleep(0.05)
        finally:
            service._calibration = None
        deadline = time.monotonic() + 300
        while c.get(f"/api/v1/jobs/{job}").json()["state"] not in (
                "completed", "failed", "aborted"):
            assert time.monotonic() < deadline, "the scan did not end"
            time.sleep(0.2)
        assert c.get(f"/api/v1/jobs/{job}").json()["state"] == "completed"
    wait = open_live(browser, daemon, 120)
    # The newest job's result is shown.
    wait.until(lambda d: f"job {job}" in _text(d, "result-job"))
    wait.until(lambda d: _text(d, "headline-calibration") != "")
    head = _text(browser, "headline-calibration")
    assert head.startswith("Calibrated, but not for this scan"), head
    assert "measured at exposure 0.005 s, this scan at 0.01 s" in head, head
    assert browser.execute_script(
        "return document.getElementById('headline-calibration').className") == "uncalibrated"


def test_start_scan_at_another_exposure_shows_the_refusal_and_queues_nothing(
    daemon: Daemon, browser: Any  # noqa: F811
) -> None:
    """A scan at another exposure than the calibration in effect is refused at submission
    (422, tests/system/api/test_exposure_warning.py); on the page the refusal must reach the
    lab in the daemon's own words (both exposures and what to do), not as a bare status, and
    the job list must stay as it was."""
    from selenium.webdriver.common.by import By

    from tests.system.api.test_browser import click_when_steady

    _calibrate(daemon)  # at 0.005 s
    with daemon.client() as c:
        before = len(c.get("/api/v1/jobs").json())
    wait = open_live(browser, daemon, 60)
    field = browser.find_element(By.ID, "scan-form").find_element(By.NAME, "exposure_s")
    field.clear()
    field.send_keys("0.5")
    click_when_steady(wait, "#start-scan")
    message = browser.find_element(By.ID, "message")
    wait.until(lambda d: message.is_displayed() and "0.5 s" in message.text)
    said = message.text
    assert "reads at exposure 0.5 s" in said and "measured at 0.005 s" in said, said
    assert "calibrate at 0.5 s first" in said, said
    assert "422" not in said and "Unprocessable" not in said, said
    with daemon.client() as c:
        assert len(c.get("/api/v1/jobs").json()) == before  # nothing queued
