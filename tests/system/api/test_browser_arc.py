"""The lab page shows a dry run's warnings: a half-turn plan on a daemon whose basis lacks the
twofold symmetry (the ``odd_daemon`` fixture), in headless Chromium (skipped without it, as
test_browser is)."""

from __future__ import annotations

from typing import Any

import pytest

from tests.system.api.conftest import Daemon
from tests.system.api.test_arc_check import says_what_and_what_to_do
from tests.system.api.test_browser import (  # noqa: F401  (the fixture)
    _calibrate,
    browser,
    click_when_steady,
    open_live,
)

pytestmark = pytest.mark.system


def test_the_page_shows_the_dry_runs_warning(odd_daemon: Daemon,
                                             browser: Any) -> None:  # noqa: F811
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import Select

    # Calibrated first, as `gonio serve --sim` does: the only warning left is the arc's.
    _calibrate(odd_daemon)
    wait = open_live(browser, odd_daemon, 60)
    form = browser.find_element(By.ID, "scan-form")
    Select(form.find_element(By.NAME, "kind")).select_by_value("uniform")
    # At the calibration's exposure (_calibrate's 0.005 s): another one draws the exposure
    # warning of the dry run.
    exposure = form.find_element(By.NAME, "exposure_s")
    exposure.clear()
    exposure.send_keys("0.005")
    arc = Select(form.find_element(By.NAME, "span_deg"))
    arc.select_by_value("180")
    warnings = browser.find_element(By.ID, "dry-run-warnings")
    assert not warnings.is_displayed()
    click_when_steady(wait, "#dry-run")
    # Not a bare "OK" when there is something to read.
    wait.until(lambda d: d.find_element(By.ID, "dry-run-result").text.startswith(
        "Runs, but read the warnings below"))
    assert warnings.is_displayed()
    (item,) = warnings.find_elements(By.TAG_NAME, "li")
    says_what_and_what_to_do(item.text)
    # A full turn, checked again: no warning left over from the half turn.
    browser.execute_script("document.getElementById('dry-run-result').textContent = ''")
    arc.select_by_value("360")
    click_when_steady(wait, "#dry-run")
    wait.until(lambda d: d.find_element(By.ID, "dry-run-result").text.startswith("OK"))
    assert not warnings.is_displayed() and warnings.find_elements(By.TAG_NAME, "li") == []
