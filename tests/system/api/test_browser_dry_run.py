"""The lab page's "Check plan" note (POST /api/v1/jobs/dry-run) in headless Chromium: its
parts add up to its total, a short exposure total is not "0 s", and it names the angle the
stage chip names. A newcomer read "about 8 s from the stage at 517.5° (moves 6 s, exposures
0 s)" beside a chip saying "specimen at 157.5°": 6 + 0 is not 8 (the settling was left out),
the scan's 25 exposures of 0.01 s were "0 s", and 517.5° was nowhere else on the page."""

from __future__ import annotations

import re
from typing import Any

import pytest

from tests.system.api.conftest import Daemon
from tests.system.api.test_browser import (  # noqa: F401
    browser,
    check_plan,
    click_when_steady,
    open_live,
)

pytestmark = pytest.mark.system

EXPOSURE_S = 0.01
ROTATIONS = 8


def _seconds(text: str) -> float:
    """A time as the note writes it ("0.25 s", "7.3 s", "40 s", "3 min") in seconds."""
    number, unit = text.split()
    return float(number) * {"s": 1, "min": 60, "h": 3600}[unit]


def test_check_plan_adds_up_and_names_the_specimen_angle(
        daemon: Daemon, browser: Any,  # noqa: F811 (the fixture)
) -> None:
    from selenium.webdriver.common.by import By

    with daemon.client() as c:
        # One and a quarter turns: the stage's position (450°) is not the specimen's angle.
        r = c.post("/api/v1/rig/stage", json={"action": "move", "angle_deg": 450.0})
        assert r.status_code == 200, r.text
        lights = len(c.get("/api/v1/rig").json()["description"]["lights"])
    wait = open_live(browser, daemon, 60)
    # 450 - 360 = 90 degrees.
    wait.until(lambda d: d.find_element(By.ID, "stage-chip").text.startswith("specimen at 90.0°"))
    note = check_plan(browser, wait, (("rotations", ROTATIONS), ("exposure_s", EXPOSURE_S),
                                      ("averages", 1)))

    # The angle the chip gives, and the stage's own position beside it.
    assert "from the specimen at 90.0° (stage position 450.0°)" in note, note
    m = re.search(r"about (\S+ \S+) from .*: moves (\S+ \S+), settling (\S+ \S+), "
                  r"exposures (\S+ \S+)\.", note)
    assert m, note
    total, moves, settling, exposures = (_seconds(g) for g in m.groups())
    # One exposure per light at each angle and one dark (`dark` = `once`, the default:
    # docs/engine.md), each 0.01 s.
    assert exposures == pytest.approx((ROTATIONS * lights + 1) * EXPOSURE_S, rel=0.05), note
    # docs/api.md: estimated_s = motion_s + settle_s + exposure_s; shown to 0.1 s.
    assert moves > 0 and settling > 0, note
    assert moves + settling + exposures == pytest.approx(total, abs=0.16), note
    # The rig's layout stands off the mirror direction: the note says so, from the API's own
    # sentence (test_time_api checks its number).
    with daemon.client() as c:
        gap = c.post("/api/v1/jobs/dry-run", json={"plan": {
            "kind": "uniform", "rotations": ROTATIONS}}).json()["mirror_gap"]
    assert gap and f"Note: {gap}." in note, note


def test_check_plan_of_one_angle_says_one_stage_angle(
        daemon: Daemon, browser: Any,  # noqa: F811 (the fixture)
) -> None:
    """A one-angle plan's note read "12 readings at 1 stage angles"."""
    from selenium.webdriver.common.by import By

    wait = open_live(browser, daemon, 60)
    form = browser.find_element(By.ID, "scan-form")
    for name, value in (("rotations", 1), ("exposure_s", EXPOSURE_S), ("averages", 1)):
        field = form.find_element(By.NAME, name)
        field.clear()
        field.send_keys(str(value))
    click_when_steady(wait, "#dry-run")
    wait.until(lambda d: "readings at" in d.find_element(By.ID, "dry-run-result").text)
    note = browser.find_element(By.ID, "dry-run-result").text
    assert re.search(r"\d+ readings at 1 stage angle, about", note), note


@pytest.mark.parametrize(("name", "value"), [("averages", "0"), ("exposure_s", "0"),
                                             ("rotations", "0")])
def test_check_plan_refuses_what_the_form_itself_refuses_as_start_does(
        daemon: Daemon, browser: Any, name: str, value: str,  # noqa: F811 (the fixture)
) -> None:
    """A value outside the form's own limits (index.html's min/max: at least 1 average, an
    exposure of at least 0.1 ms, at least one stage angle) is refused at the field by Start
    scan, with the browser's message there; Check plan sent it and showed the daemon's
    validation path instead ("plan.uniform.exposure.averages: Input should be greater than
    or equal to 1")."""
    from selenium.webdriver.common.by import By

    wait = open_live(browser, daemon, 60)
    field = browser.find_element(By.ID, "scan-form").find_element(By.NAME, name)
    field.clear()
    field.send_keys(value)
    browser.execute_script("window.__sent = []; const f = window.fetch;"
                           "window.fetch = (u, i) => { window.__sent.push(String(u));"
                           " return f(u, i); };")
    click_when_steady(wait, "#dry-run")
    # The field says what is wrong, where the user typed it, as Start scan's check does.
    wait.until(lambda d: d.switch_to.active_element == field)
    assert browser.execute_script("return arguments[0].validity.valid", field) is False
    assert not any("dry-run" in u for u in browser.execute_script("return window.__sent"))
    message = browser.find_element(By.ID, "message")
    assert not message.is_displayed() or "plan." not in message.text, message.text


@pytest.mark.parametrize("button", ["#dry-run", "#start-scan"])
def test_an_empty_stage_angles_field_says_what_to_enter(
        daemon: Daemon, browser: Any, button: str,  # noqa: F811 (the fixture)
) -> None:
    """An emptied "Stage angles r" was sent as 0 and answered with the daemon's own terms,
    "rotations is 0; ... (e.g. rotations=8)", a field name the page shows nowhere. The field
    itself now says what to enter and in what range, for Check plan and Start scan alike, and
    nothing is sent."""
    from selenium.webdriver.common.by import By

    wait = open_live(browser, daemon, 60)
    field = browser.find_element(By.ID, "scan-form").find_element(By.NAME, "rotations")
    field.clear()
    browser.execute_script("window.__posted = []; const f = window.fetch;"
                           "window.fetch = (u, i) => { if (i && i.method === 'POST')"
                           " window.__posted.push(String(u)); return f(u, i); };")
    click_when_steady(wait, button)
    wait.until(lambda d: d.switch_to.active_element == field)
    said = browser.execute_script("return arguments[0].validationMessage", field)
    assert "how many stage angles" in said and "1 to 3600" in said, said
    assert browser.execute_script("return window.__posted") == []
    message = browser.find_element(By.ID, "message")
    assert not message.is_displayed() or "rotations is" not in message.text, message.text
    # Once a number is typed the field is valid again.
    field.send_keys("8")
    assert browser.execute_script("return arguments[0].validity.valid", field) is True


def test_check_plan_is_judged_at_the_forms_priority(
        daemon: Daemon, browser: Any,  # noqa: F811 (the fixture)
) -> None:
    """Whether a queued calibration job runs before the scan depends on the priority the scan
    is queued at (docs/api.md); Check plan sent none, so the daemon judged every plan at 0
    while Start scan sent the form's."""
    import json

    wait = open_live(browser, daemon, 60)
    browser.execute_script("window.__bodies = []; const f = window.fetch;"
                           "window.fetch = (u, i) => { if (String(u).includes('dry-run'))"
                           " window.__bodies.push(i.body); return f(u, i); };")
    # Every field set: the plan checked does not hang on the form's defaults.
    check_plan(browser, wait, [("rotations", ROTATIONS), ("exposure_s", EXPOSURE_S),
                               ("averages", 1), ("priority", 7)])
    (body,) = browser.execute_script("return window.__bodies")
    assert json.loads(body)["priority"] == 7, body


def test_check_plan_says_start_would_be_refused_for_a_calibration_at_another_exposure(
        daemon: Daemon, browser: Any,  # noqa: F811 (the fixture)
) -> None:
    """A scan at another exposure than its calibration is refused at submission (422), but
    Check plan's verdict read "Runs, but read the warnings below" beside that warning. Here
    the calibration is a job queued before the scan (the queue held), at 0.02 s."""
    from selenium.webdriver.common.by import By

    from tests.system.api.test_exposure_warning import queue_calibration

    with daemon.client() as c:
        assert c.post("/api/v1/rig/halt").status_code == 200
        try:
            cal = queue_calibration(c, 0.02)
            wait = open_live(browser, daemon, 60)
            text = check_plan(browser, wait, [("rotations", ROTATIONS),
                                              ("exposure_s", EXPOSURE_S), ("averages", 1),
                                              ("priority", 0)])
            assert text.startswith("Start would be refused"), text
            wait.until(lambda d: d.find_element(By.ID, "dry-run-warnings").is_displayed())
            warnings = browser.find_element(By.ID, "dry-run-warnings").text
            assert f"calibration job {cal}, which runs before it, measures at " \
                   "0.02 s" in warnings, warnings
        finally:
            for job in (j["id"] for j in c.get("/api/v1/jobs", params={"state": "queued"}).json()):
                c.post(f"/api/v1/jobs/{job}/cancel")
            assert c.post("/api/v1/rig/release").status_code == 200


def test_a_queued_scan_that_will_be_refused_at_its_start_says_so_in_its_row(
        daemon: Daemon, browser: Any,  # noqa: F811 (the fixture)
) -> None:
    """A calibration job at another exposure queued at a higher priority than a waiting scan
    runs first, and the worker then refuses the scan at its turn ("not started"); the queue
    showed the scan as plainly queued. Its row now says it will be refused, in the warning
    colour, with both exposures (the job list's start_refusal, docs/api.md)."""
    from selenium.webdriver.common.by import By

    from tests.system.api.test_exposure_warning import held_queue

    with daemon.client() as c, held_queue(c):
        r = c.post("/api/v1/jobs", json={"plan": {
            "kind": "uniform", "rotations": 2, "exposure": {"exposure_s": EXPOSURE_S}}})
        assert r.status_code == 201, r.text
        scan = r.json()["id"]
        r = c.post("/api/v1/jobs", json={"priority": 5, "plan": {
            "kind": "calibration", "rotations": 2, "reference_albedo": 0.99,
            "exposure": {"exposure_s": 0.02}}})
        assert r.status_code == 201, r.text
        cal = r.json()["id"]
        wait = open_live(browser, daemon, 60)
        cell = f'#jobs tr[data-id="{scan}"] .start-refusal'
        wait.until(lambda d: d.find_elements(By.CSS_SELECTOR, cell))
        said = browser.find_element(By.CSS_SELECTOR, cell)
        assert said.text.startswith(
            "would be refused when it starts, as the queue stands: it reads at exposure "
            f"{EXPOSURE_S:g} s and "
            f"calibration job {cal}, the last to run before it, measures at 0.02 s"), said.text
        assert said.is_displayed()
        # The warning colour of the page's stylesheet (--warn), not the plain reason's.
        colour = browser.execute_script(
            "return getComputedStyle(arguments[0]).color", said)
        plain = browser.execute_script(
            "const s = document.createElement('span'); s.className = 'reason';"
            "document.querySelector('#jobs td').append(s);"
            "const c = getComputedStyle(s).color; s.remove(); return c")
        assert colour != plain, (colour, plain)
