"""The lab page in headless Chromium: enter the key, start a scan, watch it, see the result."""

from __future__ import annotations

import shutil
from collections.abc import Iterator
from typing import Any

import pytest

from tests.system.api.conftest import Daemon

pytestmark = pytest.mark.system

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
CHROMEDRIVER = shutil.which("chromedriver")
webdriver = pytest.importorskip("selenium.webdriver", reason="selenium is in the test extra")

if CHROMIUM is None or CHROMEDRIVER is None:
    pytest.skip(
        "no chromium/chromedriver binary on PATH (Debian: apt-get install chromium "
        "chromium-driver); the lab page is not tested in a browser",
        allow_module_level=True,
    )


@pytest.fixture(scope="module")
def browser() -> Iterator[Any]:
    from selenium.webdriver.chrome.options import Options
    from selenium.webdriver.chrome.service import Service

    opts = Options()
    opts.binary_location = CHROMIUM  # type: ignore[assignment]
    for flag in ("--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
                 "--disable-component-update", "--disable-sync", "--no-first-run",
                 "--disable-dev-shm-usage", "--window-size=1280,1600"):
        opts.add_argument(flag)
    # An explicit driver path: selenium must not try to download one.
    driver = webdriver.Chrome(service=Service(executable_path=CHROMEDRIVER), options=opts)
    driver.set_page_load_timeout(30)
    try:
        yield driver
    finally:
        driver.quit()


def test_start_a_scan_from_the_page_and_see_the_result(daemon: Daemon, browser: Any) -> None:
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support import expected_conditions as ec
    from selenium.webdriver.support.ui import Select, WebDriverWait

    wait = WebDriverWait(browser, 120, poll_frequency=0.2)
    # The key arrives in the #fragment, as `gonio serve --sim` prints it; the page moves it to
    # sessionStorage and clears it from the address bar.
    browser.get(f"{daemon.url}/#key={daemon.key}")
    wait.until(lambda d: d.find_element(By.ID, "live-chip").text == "live")
    assert "#key" not in browser.current_url
    assert browser.execute_script("return sessionStorage.getItem('gonio.apiKey')") == daemon.key
    assert "sim" in browser.find_element(By.ID, "rig-name").text

    form = browser.find_element(By.ID, "scan-form")
    specimen = form.find_element(By.NAME, "specimen")
    specimen.clear()
    specimen.send_keys("browser sample")
    Select(form.find_element(By.NAME, "kind")).select_by_value("uniform")
    for name, value in (("rotations", "6"), ("exposure_s", "0.005")):
        field = form.find_element(By.NAME, name)
        field.clear()
        field.send_keys(value)
    browser.find_element(By.ID, "dry-run").click()
    wait.until(lambda d: d.find_element(By.ID, "dry-run-result").text.startswith("OK"))
    browser.find_element(By.ID, "start-scan").click()
    wait.until(lambda d: "queued" in d.find_element(By.ID, "dry-run-result").text
               or d.find_element(By.ID, "message").is_displayed())
    assert not browser.find_element(By.ID, "message").is_displayed(), \
        browser.find_element(By.ID, "message").text
    job_id = int(browser.find_element(By.ID, "dry-run-result").text.split()[1])

    row = f'#jobs tr[data-id="{job_id}"]'
    # Live progress: readings appear in the plot while the scan runs.
    wait.until(lambda d: len(d.find_elements(By.CSS_SELECTOR, "#readings-plot circle.reading")) > 0)
    wait.until(ec.presence_of_element_located((By.CSS_SELECTOR, f'{row}[data-state="completed"]')))
    n_pairs = len(daemon.sim.config.pair_list())
    wait.until(lambda d: len(d.find_elements(By.CSS_SELECTOR, "#readings-plot circle.reading"))
               == 6 * n_pairs)
    # The result: preview image loaded, polar plot drawn, metrics listed, download offered.
    wait.until(lambda d: d.execute_script(
        "const i = document.getElementById('preview');"
        "return !i.hidden && i.complete && i.naturalWidth > 0"))
    wait.until(lambda d: len(d.find_elements(By.CSS_SELECTOR, "#polar-plot polygon")) > 0)
    metrics = browser.find_element(By.ID, "metrics").text
    assert "rel_sample_error" in metrics
    # Long values (result_path) wrap inside the result panel: no sideways scrolling.
    assert browser.execute_script(
        "const e = document.documentElement; return e.scrollWidth <= e.clientWidth"), \
        browser.execute_script("return [document.documentElement.scrollWidth, innerWidth]")
    assert browser.find_element(By.ID, "download").is_displayed()
    assert browser.find_element(By.ID, "message").get_attribute("hidden") is not None
    # Export from the page: the control appears with the result and fetches the file.
    wait.until(lambda d: d.find_element(By.ID, "export").is_displayed())
    Select(browser.find_element(By.ID, "export-format")).select_by_value("gltf")
    browser.find_element(By.ID, "export-button").click()
    wait.until(lambda d: d.find_element(By.ID, "export-state").text.startswith(
        ("saved", "export failed")))
    assert browser.find_element(By.ID, "export-state").text == f"saved gonio-job-{job_id}-gltf.gltf"
    # No script errors on the way (network 404s would show here too).
    assert [e for e in browser.get_log("browser") if e["level"] == "SEVERE"] == []


def test_page_without_key_shows_a_clear_error(daemon: Daemon, browser: Any) -> None:
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import WebDriverWait

    browser.get(f"{daemon.url}/")
    browser.execute_script("sessionStorage.clear()")
    browser.refresh()
    wait = WebDriverWait(browser, 30, poll_frequency=0.2)
    wait.until(lambda d: d.find_element(By.ID, "live-chip").text == "live")
    browser.find_element(By.ID, "start-scan").click()
    wait.until(lambda d: d.find_element(By.ID, "message").is_displayed())
    text = browser.find_element(By.ID, "message").text
    assert "X-API-Key" in text and "enter a valid API key" in text, text
