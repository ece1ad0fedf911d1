"""The lab page in headless Chromium: enter the key, start a scan, watch it, see the result."""

from __future__ import annotations

import json
import shutil
from collections.abc import Iterator, Sequence
from typing import Any

import pytest

from tests.system.api.conftest import Daemon, export_fits_off

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


def start_chromium(back_forward_cache: bool = False) -> Any:
    """Headless Chromium under chromedriver, as every browser test drives it.

    ``back_forward_cache`` False (the tests' browser): a page left (:func:`load_page` leaves
    one each time) is discarded, not kept in the back/forward cache, so no test depends on
    how the page behaves there; no test goes back or forward. True: as a lab's browser keeps
    it (test_browser_bfcache.py)."""
    from selenium.webdriver.chrome.options import Options
    from selenium.webdriver.chrome.service import Service

    opts = Options()
    opts.binary_location = CHROMIUM  # type: ignore[assignment]
    flags = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
             "--disable-component-update", "--disable-sync", "--no-first-run",
             "--disable-dev-shm-usage", "--window-size=1280,1600"]
    if not back_forward_cache:
        flags.append("--disable-features=BackForwardCache")
    for flag in flags:
        opts.add_argument(flag)
    # An explicit driver path: selenium must not try to download one.
    driver = webdriver.Chrome(service=Service(executable_path=CHROMEDRIVER), options=opts)
    driver.set_page_load_timeout(30)
    return driver


@pytest.fixture(scope="module")
def browser() -> Iterator[Any]:
    driver = start_chromium()
    try:
        yield driver
    finally:
        driver.quit()


def _severe(browser: Any) -> list[Any]:
    return [e for e in browser.get_log("browser") if e["level"] == "SEVERE"]


def _calibrate(daemon: Daemon) -> int:
    """A white-reference calibration, as `gonio serve --sim` runs first: later scans in 1/sr."""
    import time

    before = daemon.sim.place_white_reference()
    try:
        with daemon.client() as c:
            job = c.post("/api/v1/jobs", json={"plan": {
                "kind": "calibration", "reference_albedo": 0.99, "rotations": 2,
                "exposure": {"exposure_s": 0.005}}}).json()
            deadline = time.monotonic() + 120
            while c.get(f"/api/v1/jobs/{job['id']}").json()["state"] != "completed":
                assert time.monotonic() < deadline, "calibration did not complete"
                time.sleep(0.2)
    finally:
        daemon.sim.place_specimen(before.brdf)
    return int(job["id"])


def _chart(browser: Any, canvas_id: str) -> Any:
    """What a Chart.js chart shows: its dataset labels and point counts."""
    return browser.execute_script(
        "const c = Chart.getChart(document.getElementById(arguments[0]));"
        "return c ? c.data.datasets.map(d => ({label: d.label, n: d.data.length,"
        " curve: !!d.isCurve})) : null;", canvas_id)


def load_page(browser: Any, url: str) -> None:
    """Load ``url`` as a new document: the page's scripts start again from nothing, whatever
    the tab showed before (the tests of a module share one browser).

    ``browser.get`` alone does not do that when the tab is already on the page: the page moves
    the #key fragment out of the address, so a second get of ``{url}/#key=...`` differs from
    the address shown only in its fragment, and Chromium treats it as a same-document
    navigation (a hashchange, no reload). The next test then inherited the previous one's
    selected job, polled details, open panels and filled fields. A detour through
    ``about:blank`` unloads the page whatever the current address is (the page left closes its
    event stream; the browser fixture keeps no back/forward cache, so it is discarded), and the
    get that follows is a new navigation. (``refresh()``
    after the get would reload too, but only after the old page had already taken the
    fragment's key, and it reloads the address without the key, so the #key path would not
    be the one tested.) The tab's sessionStorage stays, as it does across a reload.
    """
    browser.get("about:blank")
    browser.get(url)


def open_live(browser: Any, daemon: Daemon, timeout_s: float, poll_s: float = 0.2) -> Any:
    """Open a freshly loaded page (:func:`load_page`) with the daemon's key in the #fragment
    (as `gonio serve --sim` prints it) and wait until its event stream is live; returns the
    WebDriverWait used."""
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import WebDriverWait

    wait = WebDriverWait(browser, timeout_s, poll_frequency=poll_s)
    load_page(browser, f"{daemon.url}/#key={daemon.key}")
    wait.until(lambda d: d.find_element(By.ID, "live-chip").text == "live")
    return wait


def check_plan(browser: Any, wait: Any, values: Sequence[tuple[str, object]]) -> str:
    """Fill the scan form's fields (``(name, value)`` pairs), press Check plan and return the
    dry run's note once it is shown."""
    from selenium.webdriver.common.by import By

    form = browser.find_element(By.ID, "scan-form")
    for name, value in values:
        field = form.find_element(By.NAME, name)
        field.clear()
        field.send_keys(str(value))
    click_when_steady(wait, "#dry-run")
    wait.until(lambda d: "readings at" in d.find_element(By.ID, "dry-run-result").text)
    return str(browser.find_element(By.ID, "dry-run-result").text)


def click_when_steady(wait: Any, css: str) -> None:
    """Click what ``css`` selects once it is shown and enabled. The page redraws its tables as
    events arrive, so an element found a moment ago may be replaced before the click (a stale
    element, on a busy machine most of all): find it again and click again."""
    from selenium.common.exceptions import (
        ElementClickInterceptedException,
        NoSuchElementException,
        StaleElementReferenceException,
        TimeoutException,
    )
    from selenium.webdriver.common.by import By

    last: list[str] = []

    def attempt(browser: Any) -> bool:
        try:
            element = browser.find_element(By.CSS_SELECTOR, css)
            if not (element.is_displayed() and element.is_enabled()):
                last[:] = [f"{css} is not shown and enabled"]
                return False
            element.click()
        except (StaleElementReferenceException, NoSuchElementException,
                ElementClickInterceptedException) as exc:
            last[:] = [f"{type(exc).__name__}: {exc.msg}"]
            return False
        return True

    try:
        wait.until(attempt)
    except TimeoutException:
        # Say why the click never landed (an overlay, a missing element), not only a timeout.
        raise TimeoutException(f"could not click {css}: {last[-1] if last else 'no attempt'}"
                               ) from None


def test_start_a_scan_from_the_page_and_see_the_result(daemon: Daemon, browser: Any) -> None:
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support import expected_conditions as ec
    from selenium.webdriver.support.ui import Select, WebDriverWait

    browser.get_log("browser")  # drop what tests before this one left (a keyless page's 401)
    wait = WebDriverWait(browser, 180, poll_frequency=0.2)
    cal_id = _calibrate(daemon)
    # The key arrives in the #fragment, as `gonio serve --sim` prints it; the page moves it to
    # sessionStorage and clears it from the address bar.
    load_page(browser, f"{daemon.url}/#key={daemon.key}")
    wait.until(lambda d: d.find_element(By.ID, "live-chip").text == "live")
    assert "#key" not in browser.current_url
    assert browser.execute_script("return sessionStorage.getItem('gonio.apiKey')") == daemon.key
    assert "sim" in browser.find_element(By.ID, "rig-name").text
    # The newest job is the completed calibration: it is selected and explained, and no error
    # shows before the user has done anything (it used to: a calibration has no preview).
    wait.until(lambda d: "Calibration completed" in d.find_element(By.ID, "result-state").text)
    assert f"job {cal_id}" in browser.find_element(By.ID, "result-job").text
    assert not browser.find_element(By.ID, "message").is_displayed(), \
        browser.find_element(By.ID, "message").text

    form = browser.find_element(By.ID, "scan-form")
    # Only the chosen plan kind's fields show.
    kind = Select(form.find_element(By.NAME, "kind"))
    # (A calibration reads the white reference: no specimen name; it carried the last
    # scan's into the queue while the daemon called the job "white reference".)
    shown = {
        "uniform": {"specimen", "rotations", "span_deg"},
        "adaptive": {"specimen", "initial_rotations", "rule", "min_gain", "max_rotations",
                     "span_deg"},
        "calibration": {"rotations", "reference_albedo"},
    }
    for value, visible in shown.items():
        kind.select_by_value(value)
        for name in ("specimen", "rotations", "initial_rotations", "rule", "min_gain",
                     "threshold", "max_rotations", "reference_albedo", "span_deg"):
            assert form.find_element(By.NAME, name).is_displayed() == (name in visible), \
                (value, name)

    kind.select_by_value("uniform")
    specimen = form.find_element(By.NAME, "specimen")
    specimen.clear()
    specimen.send_keys("browser sample")
    for name, value in (("rotations", "6"), ("exposure_s", "0.005")):
        field = form.find_element(By.NAME, name)
        field.clear()
        field.send_keys(value)
    click_when_steady(wait, "#dry-run")
    wait.until(lambda d: d.find_element(By.ID, "dry-run-result").text.startswith("OK"))
    # The last calibration left the stage somewhere: the estimate says it starts from there.
    assert "from the specimen at" in browser.find_element(By.ID, "dry-run-result").text
    click_when_steady(wait, "#start-scan")
    new_row = "//tbody[@id='jobs']/tr[td[2][text()='browser sample']]"
    wait.until(lambda d: d.find_elements(By.XPATH, new_row)
               or d.find_element(By.ID, "message").is_displayed())
    assert not browser.find_element(By.ID, "message").is_displayed(), \
        browser.find_element(By.ID, "message").text
    # The table is redrawn on every event: read the id in one script call.
    job_id = int(browser.execute_script(
        "return [...document.querySelectorAll('#jobs tr')]"
        ".find(r => r.children[1].textContent === 'browser sample').dataset.id"))

    row = f'#jobs tr[data-id="{job_id}"]'
    # Live progress: readings appear in the plot while the scan runs.
    wait.until(lambda d: (_chart(d, "readings-plot") or [{"n": 0}])[0]["n"] > 0)
    wait.until(ec.presence_of_element_located((By.CSS_SELECTOR, f'{row}[data-state="completed"]')))
    # "Job N queued." is no longer true once the job has run: it is gone.
    wait.until(lambda d: "queued" not in d.find_element(By.ID, "dry-run-result").text)
    n_pairs = len(daemon.sim.config.pair_list())
    # The rotation plot: each pair's 6 samples and the reconstruction's curve through them.
    wait.until(lambda d: sum(1 for s in _chart(d, "readings-plot") or [] if s["curve"]) == n_pairs)
    series = _chart(browser, "readings-plot")
    assert sorted(s["n"] for s in series if not s["curve"]) == [6] * n_pairs
    assert len({s["label"] for s in series}) == 2 * n_pairs
    # The rendering: truth (the simulated material) above the reconstruction, 512 px views.
    wait.until(lambda d: d.execute_script(
        "const i = document.getElementById('render');"
        "return !i.hidden && i.complete && i.naturalWidth > 0"))
    w, h = browser.execute_script(
        "const i = document.getElementById('render'); return [i.naturalWidth, i.naturalHeight]")
    assert w >= 5 * 512 and h >= 2 * 512, (w, h)  # five views, two rows
    # The colour panel: this rig's RGB sensors have no spectral bands or chart calibration, so
    # it shows channel values under that name, with no illuminant or observer named.
    wait.until(lambda d: "reflectance factors per channel" in
               d.find_element(By.ID, "colour-caption").text)
    caption = browser.find_element(By.ID, "colour-caption").text
    # The result's reconstruction warnings, which travel with its colour as with its exports
    # (this rig's material: the basis misfit), come first; the statement follows them.
    statement = caption[caption.index("uncalibrated sensor RGB"):]
    assert statement.startswith("uncalibrated sensor RGB: reflectance factors"), caption
    assert "D65" not in caption, caption
    # Polar plots with the reconstruction and the truth, units in the subtitle.
    wait.until(lambda d: _chart(d, "polar-in") is not None and _chart(d, "polar-cross"))
    labels = [s["label"] for s in _chart(browser, "polar-in")]
    assert any(lab.startswith("truth") for lab in labels), labels
    click_when_steady(wait, "#polar-log")
    wait.until(lambda d: d.execute_script(
        "return Chart.getChart(document.getElementById('polar-in'))"
        ".options.plugins.subtitle.text.includes('log scale')"))
    # One error number, explained; the others behind "All metrics".
    head = browser.find_element(By.ID, "headline-error").text
    # predicted_log_rmse when the reconstruction reports it, else predicted_error; either way
    # the number comes with what it means.
    assert head.startswith("predicted") and ("lower is better" in head
                                             or "expected to be off" in head), head
    assert not browser.find_element(By.ID, "metrics").is_displayed()
    click_when_steady(wait, "#metrics-details summary")
    assert "rel_sample_error" in browser.find_element(By.ID, "metrics").text
    wait.until(lambda d: d.execute_script(
        "const i = document.getElementById('preview');"
        "return !i.hidden && i.complete && i.naturalWidth > 0"))
    assert browser.find_element(By.ID, "download").is_displayed()
    # Saved under the daemon's name: the job and its specimen (gonio-job-N.h5 said neither
    # which specimen it was).
    browser.execute_script(
        "window.__saved = [];"
        "HTMLAnchorElement.prototype.click = function () { window.__saved.push(this.download); };")
    click_when_steady(wait, "#download")
    wait.until(lambda d: d.execute_script("return window.__saved.length"))
    assert browser.execute_script("return window.__saved") == [
        f"gonio-job-{job_id}-browser-sample.h5"]

    # A comparison: a second scan, chosen in "Compare with". Its export fits are not under
    # test (the export below is the first scan's): it finishes without them.
    with export_fits_off(daemon), daemon.client() as c:
        other = c.post("/api/v1/jobs", json={"plan": {
            "kind": "uniform", "specimen": "second", "rotations": 4,
            "exposure": {"exposure_s": 0.005}}}).json()["id"]
        wait.until(ec.presence_of_element_located(
            (By.CSS_SELECTOR, f'#jobs tr[data-id="{other}"][data-state="completed"]')))
    wait.until(lambda d: str(other) in [o.get_attribute("value") for o in
                                        d.find_elements(By.CSS_SELECTOR, "#compare option")])
    Select(browser.find_element(By.ID, "compare")).select_by_value(str(other))
    wait.until(lambda d: f"job {other} (bottom)" in d.find_element(By.ID, "render-caption").text)
    wait.until(lambda d: any(f"job {other}" in s["label"] for s in _chart(d, "polar-in")))
    assert browser.find_element(By.ID, "compare-plot").is_displayed()
    assert sum(1 for s in _chart(browser, "compare-plot") if s["curve"]) == n_pairs
    # Nothing forces a horizontal scrollbar, no message is standing, no script errors.
    assert browser.execute_script(
        "return document.documentElement.scrollWidth <= window.innerWidth")
    assert browser.find_element(By.ID, "message").get_attribute("hidden") is not None
    # Export from the page: the control appears with the result and fetches the file.
    wait.until(lambda d: d.find_element(By.ID, "export").is_displayed())
    Select(browser.find_element(By.ID, "export-format")).select_by_value("gltf")
    click_when_steady(wait, "#export-button")
    wait.until(lambda d: d.find_element(By.ID, "export-state").text.startswith(
        ("saved", "export failed")))
    # (Then the file's warnings, one a line: this small test basis leaves a misfit.)
    first = browser.find_element(By.ID, "export-state").text.split("\n")[0]
    assert first == f"saved gonio-job-{job_id}-browser-sample-gltf.gltf", first
    # The default choice is the material on a preview sphere, which any glTF viewer shows
    # (the material alone is an empty scene there): the daemon's with_mesh file.
    Select(browser.find_element(By.ID, "export-format")).select_by_index(0)
    click_when_steady(wait, "#export-button")
    wait.until(lambda d: "gltf-mesh" in d.find_element(By.ID, "export-state").text
               or "export failed" in d.find_element(By.ID, "export-state").text)
    first = browser.find_element(By.ID, "export-state").text.split("\n")[0]
    assert first == f"saved gonio-job-{job_id}-browser-sample-gltf-mesh.gltf", first
    # The binary glTF on its sphere, for viewers that open .glb files (Blender, model-viewer).
    Select(browser.find_element(By.ID, "export-format")).select_by_value("glb-mesh")
    click_when_steady(wait, "#export-button")
    wait.until(lambda d: "glb-mesh" in d.find_element(By.ID, "export-state").text
               or "export failed" in d.find_element(By.ID, "export-state").text)
    first = browser.find_element(By.ID, "export-state").text.split("\n")[0]
    assert first == f"saved gonio-job-{job_id}-browser-sample-glb-mesh.glb", first
    # The export's warnings, as `gonio export` prints them (the daemon sends them in a header,
    # test_scan_flow), one a line beside the file's name: the download cannot say them.
    Select(browser.find_element(By.ID, "export-format")).select_by_value("merl")
    click_when_steady(wait, "#export-button")
    wait.until(lambda d: d.find_element(By.ID, "export-state").text.startswith(
        (f"saved gonio-job-{job_id}-browser-sample-merl", "export failed")))
    state = browser.find_element(By.ID, "export-state").text.split("\n")
    with daemon.client() as c:
        sent = json.loads(c.get(f"/api/v1/jobs/{job_id}/export", params={"format": "merl"})
                          .headers["x-gonio-export-warnings"])
    assert sent, "no warning to show"  # this small test basis leaves a misfit, at least
    # With its provenance sidecar, saved beside it as gonio export writes it.
    assert state == [f"saved gonio-job-{job_id}-browser-sample-merl.binary and "
                     f"gonio-job-{job_id}-browser-sample-merl.binary.json",
                     *(f"warning: {w}" for w in sent)]
    # A 600 px window: the export row wraps inside it (its menu's longest option pushed the
    # page 80 px wider than the window, the Export button off screen).
    browser.set_window_size(600, 900)
    try:
        wait.until(lambda d: d.execute_script(
            "const b = document.getElementById('export-button').getBoundingClientRect();"
            "return document.documentElement.scrollWidth <= window.innerWidth"
            " && b.right <= window.innerWidth"))
    finally:
        browser.set_window_size(1280, 1600)
    # The calibration selected: it has no result and no "Compare with", so the comparison's
    # readings go too (they stayed, beside the calibration's own); back on the scan, they show.
    click_when_steady(wait, f'#jobs tr[data-id="{cal_id}"]')
    wait.until(lambda d: "Calibration completed" in d.find_element(By.ID, "result-state").text)
    assert not browser.find_element(By.ID, "compare-plot").is_displayed()
    click_when_steady(wait, row)
    wait.until(lambda d: d.find_element(By.ID, "compare-plot").is_displayed())
    # The export line spoke of this job's files: another job's result shown, it is emptied
    # (job 12's panel said "saved gonio-job-9-...").
    click_when_steady(wait, f'#jobs tr[data-id="{other}"]')
    wait.until(lambda d: d.find_element(By.ID, "result-job").text == f"job {other} (completed)")
    assert browser.find_element(By.ID, "export-state").text == ""
    assert _severe(browser) == []


def test_an_adaptive_plan_from_the_page_sets_its_rule(daemon: Daemon, browser: Any,
                                                      no_export_fits: None) -> None:
    """Rule and min gain on the form, explained, checked by the server, shown with the job."""
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support import expected_conditions as ec
    from selenium.webdriver.support.ui import Select

    browser.get_log("browser")  # drop what tests before this one left (a keyless page's 401)
    # Its own calibration (at 0.005 s): uncalibrated, Check plan says Start would be refused.
    _calibrate(daemon)
    wait = open_live(browser, daemon, 180)
    form = browser.find_element(By.ID, "scan-form")

    def fill(name: str, value: str) -> None:
        field = form.find_element(By.NAME, name)
        field.clear()
        field.send_keys(value)

    # At the calibration's exposure: at the form's default, another exposure, Check plan
    # says Start would be refused.
    fill("exposure_s", "0.005")
    Select(form.find_element(By.NAME, "kind")).select_by_value("adaptive")
    rule = Select(form.find_element(By.NAME, "rule"))
    # Defaults shown: the posterior rule and the calibrated min gain, with what they mean.
    assert rule.first_selected_option.get_attribute("value") == "posterior"
    assert form.find_element(By.NAME, "min_gain").get_attribute("value") == "0.00002"
    help_text = browser.find_element(By.ID, "rule-help").text
    assert "min gain" in help_text and "threshold e" in help_text and "default" in help_text
    assert form.find_element(By.NAME, "initial_rotations").get_attribute("value") == "4"
    assert form.find_element(By.NAME, "max_rotations").get_attribute("value") == "16"
    assert "max angles" in help_text
    # The setting of the rule not chosen is hidden; each rule's default first round and cap
    # show (vf: no cap, an empty field).
    rule.select_by_value("vf")
    assert form.find_element(By.NAME, "threshold").is_displayed()
    assert not form.find_element(By.NAME, "min_gain").is_displayed()
    assert form.find_element(By.NAME, "initial_rotations").get_attribute("value") == "8"
    assert form.find_element(By.NAME, "max_rotations").get_attribute("value") == ""
    arc = Select(form.find_element(By.NAME, "span_deg"))
    assert arc.first_selected_option.get_attribute("value") == "360"  # V&F's full turn
    rule.select_by_value("posterior")
    assert not form.find_element(By.NAME, "threshold").is_displayed()
    assert form.find_element(By.NAME, "initial_rotations").get_attribute("value") == "4"
    assert form.find_element(By.NAME, "max_rotations").get_attribute("value") == "16"
    assert arc.first_selected_option.get_attribute("value") == "180"
    # The dry run's bound is the cap: 4 angles, then at most 12 more.
    click_when_steady(wait, "#dry-run")
    wait.until(lambda d: d.find_element(By.ID, "dry-run-result").text.startswith("OK"))
    assert "can add up to 12 angles" in browser.find_element(By.ID, "dry-run-result").text

    # A bad value reaches the server, which says what is wrong and what to do.
    fill("min_gain", "-1")
    click_when_steady(wait, "#dry-run")
    wait.until(lambda d: d.find_element(By.ID, "message").is_displayed())
    text = browser.find_element(By.ID, "message").text
    assert "min_gain" in text and "> 0" in text and "got -1" in text, text

    fill("min_gain", "0.002")
    fill("max_rotations", "3")
    click_when_steady(wait, "#dry-run")
    wait.until(lambda d: "max_rotations 3" in d.find_element(By.ID, "message").text)
    assert "fewer than the first round's 4" in browser.find_element(By.ID, "message").text

    for name, value in (("specimen", "adaptive sample"), ("initial_rotations", "4"),
                        ("min_gain", "0.002"), ("max_rotations", "6"),
                        ("exposure_s", "0.005")):
        fill(name, value)
    click_when_steady(wait, "#start-scan")
    new_row = "//tbody[@id='jobs']/tr[td[2][text()='adaptive sample']]"
    wait.until(lambda d: d.find_elements(By.XPATH, new_row))
    job_id = int(browser.execute_script(
        "return [...document.querySelectorAll('#jobs tr')]"
        ".find(r => r.children[1].textContent === 'adaptive sample').dataset.id"))
    with daemon.client() as c:
        plan = c.get(f"/api/v1/jobs/{job_id}").json()["plan"]
    assert plan["rule"] == "posterior" and plan["min_gain"] == 0.002
    assert plan["max_rotations"] == 6 and plan["span_deg"] == 180
    assert "threshold" not in plan or plan["threshold"] == 0.1  # the vf setting was not sent
    wait.until(ec.presence_of_element_located(
        (By.CSS_SELECTOR, f'#jobs tr[data-id="{job_id}"][data-state="completed"]')))
    # The job view: the readings used, with the rule that chose them.
    wait.until(lambda d: "posterior rule" in d.find_element(By.ID, "live-rule").text)
    live = browser.find_element(By.ID, "live-job").text + browser.find_element(
        By.ID, "live-rule").text
    with daemon.client() as c:
        used = len(c.get(f"/api/v1/jobs/{job_id}/readings").json())
    assert f"{used} readings" in live and "min gain 0.002" in live and "from 4 angles" in live
    assert "up to 6" in live
    # The only error logged is the refused check above (the browser logs every 422).
    assert [e["message"] for e in _severe(browser) if "dry-run" not in e["message"]] == []


def test_open_live_gives_each_test_a_freshly_loaded_page(daemon: Daemon, browser: Any) -> None:
    """The tests of a module share one browser: each must get a page whose scripts started
    anew, not the previous test's page with its selection and polled details (a get of the
    same address with only a #fragment differing does not reload it)."""
    open_live(browser, daemon, 60)
    # What a test leaves behind: script state and a document that has been running a while.
    browser.execute_script("window.__leftover = 1")
    loaded = browser.execute_script("return performance.timeOrigin")
    open_live(browser, daemon, 60)
    assert browser.execute_script("return typeof window.__leftover") == "undefined"
    assert browser.execute_script("return performance.timeOrigin") > loaded
    # The key still came from the address and left it, as on a first load.
    assert "#key" not in browser.current_url
    assert browser.execute_script("return sessionStorage.getItem('gonio.apiKey')") == daemon.key


def test_page_without_key_shows_a_clear_error(daemon: Daemon, browser: Any) -> None:
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import WebDriverWait

    load_page(browser, f"{daemon.url}/")
    browser.execute_script("sessionStorage.clear()")
    browser.refresh()
    wait = WebDriverWait(browser, 30, poll_frequency=0.2)
    wait.until(lambda d: d.find_element(By.ID, "live-chip").text == "live")
    click_when_steady(wait, "#start-scan")
    # The daemon's own refusal, said once: by the key prompt, with what to do (the message
    # box under it repeated it in other words), and it stays until a key is entered, though
    # the page's open reads go on working meanwhile.
    with daemon.client(key=None) as c:
        refusal = c.post("/api/v1/jobs", json={"plan": {"kind": "uniform"}})
    assert refusal.status_code == 401
    wait.until(lambda d: d.find_element(By.ID, "key-prompt").is_displayed())
    text = browser.find_element(By.ID, "key-prompt").text
    assert refusal.json()["detail"] in text and "paste one at the top right" in text, text
    assert not browser.find_element(By.ID, "message").is_displayed()
    # A job another client queues is read and listed (reads are open), and the prompt stays.
    with export_fits_off(daemon), daemon.client() as c:
        job = c.post("/api/v1/jobs", params={"accept_uncalibrated": "true"}, json={"plan": {
            "kind": "uniform", "specimen": "another client's", "rotations": 2,
            "exposure": {"exposure_s": 0.005}}}).json()["id"]
        wait.until(lambda d: d.execute_script(
            f"return !!document.querySelector('#jobs tr[data-id=\"{job}\"]')"))
        assert browser.find_element(By.ID, "key-prompt").is_displayed()
        assert not browser.find_element(By.ID, "message").is_displayed()
        wait.until(lambda _d: c.get(f"/api/v1/jobs/{job}").json()["state"]
                   in ("completed", "failed"))


def test_a_suspended_job_shows_why_and_the_reason_goes_when_it_recovers(
        daemon: Daemon, browser: Any, no_export_fits: None) -> None:

    browser.get_log("browser")  # drop what earlier tests left (the keyless page's 401)
    wait = open_live(browser, daemon, 120, poll_s=0.1)
    with daemon.client() as c:
        job = c.post("/api/v1/jobs", json={"plan": {
            "kind": "uniform", "specimen": "flaky", "rotations": 12,
            "exposure": {"exposure_s": 0.005},
            "faults": {"retry_delay_s": 0.5, "max_retries": 20}}}).json()["id"]
        # Once it measures (the rig is connected), a sensor stops answering for 2.5 s.
        wait.until(lambda _d: c.get(f"/api/v1/jobs/{job}").json()["done_angles"] >= 1)
        daemon.sim.apply_fault("silence:S2:2.5")

    def reason(d: Any) -> str:
        return str(d.execute_script(
            "const r = document.querySelector(`#jobs tr[data-id='${arguments[0]}']`);"
            "return r ? [r.dataset.state, r.querySelector('.reason')?.textContent ?? ''] "
            ".join('|') : '';", job))

    # The row says suspended and why (the device and what happened), not only a tooltip.
    wait.until(lambda d: reason(d).startswith("suspended|S"))
    wait.until(lambda d: reason(d) == "completed|")  # recovered: no stale reason left
    assert _severe(browser) == []
