"""The lab page's stage panel, in headless Chromium against a real daemon on the simulated
rig: a lab loading a specimen or setting the zero at the holder's mark had the command line
alone. The checks read the simulated stage itself (its physical position) and the daemon's
GET /api/v1/rig/stage, not the page's code."""

from __future__ import annotations

import re
import time
from typing import Any

import pytest

from tests.system.api.conftest import Daemon
from tests.system.api.test_browser import (  # noqa: F401 (the fixture)
    _severe,
    browser,
    click_when_steady,
    open_live,
)

pytestmark = [pytest.mark.system, pytest.mark.timeout(300)]


def test_the_page_moves_the_stage_sets_its_zero_and_says_a_refusal(
        daemon: Daemon, browser: Any,  # noqa: F811 (the fixture)
) -> None:
    from selenium.webdriver.common.by import By

    wait = open_live(browser, daemon, 120)
    def said() -> str:
        # Each line starts with the time of the command (HH:MM): it stays until the next.
        text = str(browser.find_element(By.ID, "stage-said").text)
        if not text:
            return text
        assert re.match(r"\d\d:\d\d ", text), text
        return text[6:]

    shown = lambda: str(browser.find_element(By.ID, "stage-state").text)  # noqa: E731
    field = browser.find_element(By.CSS_SELECTOR, "#stage-form [name=angle_deg]")
    with daemon.client() as c:
        start = c.get("/api/v1/rig/stage").json()["position_deg"]
    physical = daemon.sim.motion.position_deg()
    target = start + 40.0
    field.clear()
    field.send_keys(f"{target:g}")
    click_when_steady(wait, "#stage-move")
    wait.until(lambda d: said().endswith(": done") or "refused" in said())
    assert said() == f"moving to {target:g}°: done", said()
    # The stage itself moved by 40 deg, and the panel says where it is, as the daemon does.
    assert daemon.sim.motion.position_deg() == pytest.approx(physical + 40.0, abs=0.2)
    with daemon.client() as c:
        now = c.get("/api/v1/rig/stage").json()["position_deg"]
    assert now == pytest.approx(target, abs=0.2)
    assert shown().startswith(f"position {now:.2f}°"), (shown(), now)

    # The zero set here, after the question: the daemon then reads 0 and homed.
    click_when_steady(wait, "#stage-home")
    question = browser.switch_to.alert
    assert "reference mark" in question.text
    question.accept()
    wait.until(lambda d: said().startswith("setting the zero here: ")
               or "refused" in said())
    assert said() == "setting the zero here: done", said()
    with daemon.client() as c:
        st = c.get("/api/v1/rig/stage").json()
    assert st["position_deg"] == pytest.approx(0.0, abs=0.05) and st["homed"] is True, st
    assert shown().startswith("position 0.00°") and ", homed" in shown(), shown()

    # While a job is active the daemon refuses a move: its words, on the panel.
    with daemon.client() as c:
        job = c.post("/api/v1/jobs", params={"accept_uncalibrated": "true"}, json={"plan": {
            "kind": "uniform", "rotations": 72,
            "exposure": {"exposure_s": 0.02, "light_settle_s": 0.0}}}).json()["id"]
        deadline = time.monotonic() + 120
        while c.get(f"/api/v1/jobs/{job}").json()["state"] != "running":
            assert time.monotonic() < deadline, "the job never started"
            time.sleep(0.1)
        try:
            field.clear()
            field.send_keys("10")
            click_when_steady(wait, "#stage-move")
            wait.until(lambda d: "refused" in said())
            assert said().startswith("moving to 10° refused: "), said()
            assert f"job {job}" in said(), said()
        finally:
            c.post(f"/api/v1/jobs/{job}/abort")
            deadline = time.monotonic() + 120
            while c.get(f"/api/v1/jobs/{job}").json()["state"] not in ("aborted", "failed"):
                assert time.monotonic() < deadline, "the job did not end"
                time.sleep(0.1)
    assert [e for e in _severe(browser) if "status of 409" not in e["message"]] == []
