"""The lab page's rig design panel, in headless Chromium against a real daemon: the design
API (``POST /api/v1/design``, ``GET /api/v1/design/presets``) had no place on the page, so a
lab that wanted to know where to mount its lights and sensors needed curl or ``gonio design``.

The checks are independent of the code that computed the design: each pair's half and
difference angles as shown must follow from its light's and sensor's directions as shown (the
half vector, math.md), the devices must respect the height asked for, the fragment shown must
be TOML naming the same devices, and MA98 has 19 pairs (V&F 2016, Table 1)."""

from __future__ import annotations

import math
import tomllib
from typing import Any

import pytest

from tests.system.api.conftest import DESIGN_LIMIT_S, Daemon
from tests.system.api.test_browser import (  # noqa: F401 (the fixture)
    _severe,
    browser,
    click_when_steady,
    open_live,
)

pytestmark = [pytest.mark.system, pytest.mark.timeout(300)]


def _unit(theta_deg: float, phi_deg: float) -> tuple[float, float, float]:
    t, p = math.radians(theta_deg), math.radians(phi_deg)
    return (math.sin(t) * math.cos(p), math.sin(t) * math.sin(p), math.cos(t))


def _rows(page: Any) -> list[list[str]]:
    from selenium.webdriver.common.by import By

    return [[td.text for td in tr.find_elements(By.TAG_NAME, "td")]
            for tr in page.find_elements(By.CSS_SELECTOR, "#design-pairs tbody tr")]


def _check_geometry(rows: list[list[str]], max_elevation_deg: float) -> None:
    """Each row: pair, light, theta, phi, sensor, theta, phi, theta_h, theta_d, phi_d (as
    shown, one decimal): theta_h is the half vector's angle from the normal and theta_d half
    the light-sensor angle."""
    for row in rows:
        lt, lp, st, sp, th, td = (float(row[i]) for i in (2, 3, 5, 6, 7, 8))
        assert lt <= max_elevation_deg + 0.05 and st <= max_elevation_deg + 0.05, row
        light, sensor = _unit(lt, lp), _unit(st, sp)
        h = [a + b for a, b in zip(light, sensor, strict=True)]
        norm = math.sqrt(sum(x * x for x in h))
        theta_h = math.degrees(math.acos(h[2] / norm))
        cos_ls = sum(a * b for a, b in zip(light, sensor, strict=True))
        theta_d = math.degrees(math.acos(max(-1.0, min(1.0, cos_ls)))) / 2
        # The shown angles are rounded to 0.1 deg each: a few tenths between them.
        assert th == pytest.approx(theta_h, abs=0.3), row
        assert td == pytest.approx(theta_d, abs=0.3), row


def test_the_page_designs_pairs_and_evaluates_a_preset_with_its_rig_fragment(
        daemon: Daemon, browser: Any,  # noqa: F811 (the fixture)
) -> None:
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import Select

    wait = open_live(browser, daemon, 120)
    form = browser.find_element(By.ID, "design-form")

    def fill(name: str, value: str) -> None:
        field = form.find_element(By.NAME, name)
        field.clear()
        if value:
            field.send_keys(value)

    def state() -> str:
        return str(browser.find_element(By.ID, "design-state").text)

    # An empty field says what to enter, at the field, and nothing is asked of the daemon.
    fill("pairs", "")
    click_when_steady(wait, "#design-run")
    said = browser.execute_script(
        "return document.querySelector('#design-form [name=pairs]').validationMessage")
    assert "how many light/sensor pairs" in said, said
    assert state() == ""
    # A time limit above the daemon's own: its refusal, in its words, on the panel.
    fill("pairs", "3")
    fill("max_elevation_deg", "70")
    fill("time_limit_s", str(DESIGN_LIMIT_S + 5))
    click_when_steady(wait, "#design-run")
    wait.until(lambda d: "failed" in state())
    assert f"more than this daemon allows ({DESIGN_LIMIT_S:g} s)" in state(), state()
    assert browser.find_element(By.ID, "design-result").is_displayed() is False

    # A region to keep clear that does not read: the daemon's words.
    fill("time_limit_s", "")
    fill("exclusions", "cone:0,0")
    click_when_steady(wait, "#design-run")
    wait.until(lambda d: "failed" in state())
    assert "cone:0,0" in state(), state()

    # Three pairs no higher than 70 deg, none within 20 deg of the normal (a camera there),
    # in the daemon's own time limit.
    fill("exclusions", "cone:0,0,20")
    click_when_steady(wait, "#design-run")
    wait.until(lambda d: "done" in state() or "failed" in state())
    assert "done" in state(), state()
    rows = _rows(browser)
    assert len(rows) == 3, rows
    _check_geometry(rows, 70.0)
    # Outside the cone: every device more than 20 deg from the normal.
    assert all(float(r[i]) > 20.0 - 0.05 for r in rows for i in (2, 5)), rows
    summary = browser.find_element(By.ID, "design-summary").text
    assert summary.startswith("optimized, 3 pairs"), summary
    assert "a best case, not a prediction for a new specimen" in summary, summary
    # The fragment is TOML a rig config takes, naming the devices of the table.
    browser.find_element(By.CSS_SELECTOR, "#design-fragment-details summary").click()
    fragment = tomllib.loads(browser.find_element(By.ID, "design-fragment").text)
    assert {d["name"] for d in fragment["lights"]} == {r[1] for r in rows}, fragment
    assert {d["name"] for d in fragment["sensors"]} == {r[4] for r in rows}, fragment
    merge = browser.find_element(By.ID, "design-merge").text
    assert "gonio rig apply-design gonio-design-optimized-3-pairs.toml rig.toml" in merge, merge

    # Designed for colour at MA68: the summary says which pairs sit at its near-specular
    # geometries.
    fill("exclusions", "")
    Select(form.find_element(By.NAME, "colour_instrument")).select_by_value("MA68")
    click_when_steady(wait, "#design-run")
    wait.until(lambda d: "done" in state() or "failed" in state())
    assert "done" in state(), state()
    summary = browser.find_element(By.ID, "design-summary").text
    assert "colour: pairs 1-" in summary and "near-specular" in summary, summary
    Select(form.find_element(By.NAME, "colour_instrument")).select_by_value("")

    # MA98, evaluated at the form's stage angles: its 19 pairs (V&F Table 1).
    Select(browser.find_element(By.ID, "design-preset")).select_by_value("MA98")
    click_when_steady(wait, "#design-evaluate")
    wait.until(lambda d: "evaluating MA98: done" in state() or "failed" in state())
    rows = _rows(browser)
    assert len(rows) == 19, state()
    _check_geometry(rows, 90.0)
    assert browser.find_element(By.ID, "design-summary").text.startswith("MA98, 19 pairs")
    # The refused time limit's 422 is the one error the console may hold.
    assert [e for e in _severe(browser) if "status of 422" not in e["message"]] == []
