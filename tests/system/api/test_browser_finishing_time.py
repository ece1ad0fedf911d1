"""The lab page's ETA while a job finishes past its estimate: it says so, where it said
"≈ 0 s left (est.)" for as long as the finishing went on. Headless Chromium against a daemon
whose first basis load is slow (tests/system/api/conftest.py, slow_basis_daemon)."""

from __future__ import annotations

import math
import time
from typing import Any

import pytest

from gonio.timeleft import FINISHING_FALLBACK_S
from tests.system.api.conftest import Daemon
from tests.system.api.test_browser import browser, open_live  # noqa: F401 (fixture)
from tests.system.api.test_finishing_time import PLAN

pytestmark = [pytest.mark.system, pytest.mark.timeout(300)]


def test_a_finishing_past_its_estimate_says_so_instead_of_0_s_left(
    slow_basis_daemon: Daemon, browser: Any,  # noqa: F811 (the fixture)
) -> None:
    wait = open_live(browser, slow_basis_daemon, 120, poll_s=0.1)
    # Every 100 ms, the selected job's ETA cell as drawn, while it reconstructs.
    browser.execute_script("""
        window.__eta = [];
        window.__watch = setInterval(() => {
          const row = document.querySelector('#jobs tr[data-state="reconstructing"]');
          if (row) window.__eta.push(row.querySelector('td.eta').textContent);
        }, 100);""")
    with slow_basis_daemon.client() as c:
        job = c.post("/api/v1/jobs", params={"accept_uncalibrated": "true"},
                     json={"plan": PLAN}).json()["id"]
        deadline = time.monotonic() + 240
        while c.get(f"/api/v1/jobs/{job}").json()["state"] != "completed":
            assert time.monotonic() < deadline, "the scan did not complete"
            time.sleep(0.2)
    wait.until(lambda d: d.execute_script(
        f"return document.querySelector('#jobs tr[data-id=\"{job}\"]')?.dataset.state")
        == "completed")
    shown = browser.execute_script("clearInterval(window.__watch); return window.__eta")
    assert shown, "the page never showed the job reconstructing"
    assert not any("≈ 0 s left" in s for s in shown), sorted(set(shown))
    # The estimate before any finished scan, as the page rounds seconds (Math.round).
    estimated = math.floor(FINISHING_FALLBACK_S + 0.5)
    assert any(f"taking longer than the ≈ {estimated} s estimated" in s for s in shown), \
        sorted(set(shown))
