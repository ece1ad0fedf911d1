"""The lab page and an auto-arc plan (issue 25): the scan form's arc "from the data", the dry
run's two branches, and the finished job's headline saying which arc its first round chose
and why, in headless Chromium (skipped without it, as test_browser is). The simulated rig's
default material is twofold symmetric, so the job stays on half a turn."""

from __future__ import annotations

from typing import Any

import pytest

from tests.system.api.conftest import Daemon
from tests.system.api.test_browser import (  # noqa: F401  (the fixture)
    _calibrate,
    browser,
    click_when_steady,
    open_live,
)

pytestmark = pytest.mark.system


def test_the_page_runs_an_auto_arc_plan_and_says_which_arc(daemon: Daemon,
                                                            browser: Any) -> None:  # noqa: F811
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support import expected_conditions as ec
    from selenium.webdriver.support.ui import Select

    _calibrate(daemon)
    wait = open_live(browser, daemon, 180)
    form = browser.find_element(By.ID, "scan-form")
    Select(form.find_element(By.NAME, "kind")).select_by_value("uniform")
    specimen = form.find_element(By.NAME, "specimen")
    specimen.clear()
    specimen.send_keys("auto arc")
    for name, value in (("rotations", "4"), ("exposure_s", "0.005")):
        field = form.find_element(By.NAME, name)
        field.clear()
        field.send_keys(value)
    Select(form.find_element(By.NAME, "span_deg")).select_by_value("auto")
    click_when_steady(wait, "#dry-run")
    wait.until(lambda d: "If the first round finds" in d.find_element(By.ID,
                                                                      "dry-run-result").text)
    text = browser.find_element(By.ID, "dry-run-result").text
    # 4 over half a turn plus the opposite of 0 (the simulated rig's pairs lie in planes
    # spread around the normal, so one opposite tests it): 5 angles; a full turn adds 3 more.
    assert "at 5 stage angles" in text
    assert "twofold symmetric, it goes on over half a turn: at most 5 angles" in text
    assert "not twofold symmetric, it goes on over a full turn: at most 8 angles" in text
    click_when_steady(wait, "#start-scan")
    row = "//tbody[@id='jobs']/tr[td[2][text()='auto arc']]"
    wait.until(lambda d: d.find_elements(By.XPATH, row)
               or d.find_element(By.ID, "message").is_displayed())
    job_id = int(browser.execute_script(
        "return [...document.querySelectorAll('#jobs tr')]"
        ".find(r => r.children[1].textContent === 'auto arc').dataset.id"))
    wait.until(ec.presence_of_element_located(
        (By.CSS_SELECTOR, f'#jobs tr[data-id="{job_id}"][data-state="completed"]')))
    wait.until(lambda d: "Scanned over" in d.find_element(By.ID, "headline-error").text)
    head = browser.find_element(By.ID, "headline-error").text
    assert "Scanned over half a turn" in head and "twofold symmetric" in head, head
    # The preview image arrives after the job completes and moves the page: a plain click can
    # land on it (CI, 2026-11-27); click once the summary is where the click goes.
    click_when_steady(wait, "#metrics-details summary")
    metrics = browser.find_element(By.ID, "metrics").text
    assert "arc_test_p_value" in metrics and "arc_deg" in metrics
