"""The lab page's Check plan does not say 'Runs' for a plan the calibration in effect covers
only in part: Start refuses such a plan (422, a result is calibrated in full or not at all),
while the check said 'Runs, but read the warnings below' beside a warning that the values
would stay in sensor units. Headless Chromium against the real daemon on the simulated rig,
as tests/system/api/test_browser.py."""

from __future__ import annotations

from typing import Any

import pytest

from tests.system.api.conftest import Daemon
from tests.system.api.test_browser import (  # noqa: F401 (fixture)
    browser,
    click_when_steady,
    open_live,
)
from tests.system.daemon_proc import wait_for

pytestmark = [pytest.mark.system, pytest.mark.timeout(600)]


def test_check_plan_says_a_partly_calibrated_plan_would_be_refused(
    daemon: Daemon, browser: Any  # noqa: F811
) -> None:
    from selenium.webdriver.common.by import By

    # A calibration of one pair only: the page's default plan measures every pair.
    before = daemon.sim.place_white_reference()
    try:
        with daemon.client() as c:
            plan = {"kind": "calibration", "rotations": 2, "reference_albedo": 0.99,
                    "pairs": [{"light": "L1", "sensor": "S1"}]}
            job = c.post("/api/v1/jobs", json={"plan": plan}).json()["id"]
            wait_for(lambda: c.get(f"/api/v1/jobs/{job}").json()["state"]
                     in ("completed", "failed"), what="the calibration job")
            assert c.get(f"/api/v1/jobs/{job}").json()["state"] == "completed"
    finally:
        daemon.sim.place_specimen(before.brdf)
    wait = open_live(browser, daemon, 120)
    click_when_steady(wait, "#dry-run")
    wait.until(lambda d: d.find_element(By.ID, "dry-run-warnings").is_displayed())
    text = browser.find_element(By.ID, "dry-run-result").text
    assert text.startswith("Start would be refused"), text
    warnings = browser.find_element(By.ID, "dry-run-warnings").text
    assert "not calibrated" in warnings and "would be refused" in warnings, warnings
