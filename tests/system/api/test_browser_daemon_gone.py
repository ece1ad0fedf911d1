"""The lab page while its daemon is stopped and started again (Ctrl-C and the same command
again, a crash and systemd's restart): the page says in words that the daemon does not answer,
where it showed the browser's "TypeError: Failed to fetch", and the message goes once the
daemon answers again. Headless Chromium against a real daemon on loopback, stopped and
started again on the same port, data directory and simulated rig."""

from __future__ import annotations

import secrets
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from gonio.api.auth import ApiKeyring
from gonio.basis_supply import BasisSupply
from gonio.daemon import DaemonConfig, build_app
from tests.system.api.conftest import Daemon
from tests.system.api.live_server import live_server
from tests.system.api.test_browser import browser, click_when_steady, open_live  # noqa: F401

pytestmark = [pytest.mark.system, pytest.mark.timeout(240)]


@pytest.fixture
def sim() -> Iterator[Any]:
    from gonio.sim.rig import SimRigOptions, start_sim_rig

    rig = start_sim_rig(SimRigOptions(time_scale=10.0, settle_s=0.0))
    try:
        yield rig
    finally:
        rig.close()


def _app(data_dir: Path, sim: Any, key: str, basis: Any) -> Any:
    """A daemon's app on ``data_dir`` and the simulated rig, as each start of the daemon
    builds it."""
    cfg = DaemonConfig().with_overrides(paths__data_dir=str(data_dir))
    return build_app(cfg, sim.config, ApiKeyring({"tester": key}),
                     basis=BasisSupply(lambda: basis))


def _message(d: Any) -> str:
    from selenium.webdriver.common.by import By

    box = d.find_element(By.ID, "message")
    return str(box.text) if box.is_displayed() else ""


def test_the_page_says_the_daemon_does_not_answer_until_it_is_back(
        tmp_path: Path, sim: Any, basis: Any, browser: Any,  # noqa: F811 (the fixture)
) -> None:
    from selenium.webdriver.common.by import By

    key = secrets.token_hex(24)
    data_dir = tmp_path / "data"
    first = _app(data_dir, sim, key, basis)
    with live_server(first) as url:
        wait = open_live(browser, Daemon(url, key, first, sim, data_dir), 60, poll_s=0.1)
    port = int(url.rsplit(":", 1)[1])

    # Stopped: the page's next refresh fails, and it says why in words.
    wait.until(_message)
    shown = _message(browser)
    assert "TypeError" not in shown and "Failed to fetch" not in shown, shown
    assert f"The daemon at {url} does not answer" in shown, shown
    assert "reconnects by itself" in shown, shown
    assert browser.find_element(By.ID, "live-chip").text == "reconnecting"

    # A user's action while it is down meets the same words.
    click_when_steady(wait, "#dry-run")
    wait.until(lambda d: f"The daemon at {url} does not answer" in _message(d))

    # Started again on the same port and data directory: the page is live again by itself,
    # and the next action works and clears the message.
    second = _app(data_dir, sim, key, basis)
    with live_server(second, port=port):
        wait.until(lambda d: d.find_element(By.ID, "live-chip").text == "live")
        click_when_steady(wait, "#dry-run")
        wait.until(lambda d: "readings at 8 stage angles"
                   in d.find_element(By.ID, "dry-run-result").text)
        assert _message(browser) == ""


def _polar_labels(d: Any) -> list[str]:
    labels = d.execute_script(
        "const c = Chart.getChart(document.getElementById('polar-in'));"
        "return c ? c.data.datasets.map(s => s.label) : null;")
    return list(labels or [])


def test_a_result_that_failed_to_load_while_the_daemon_was_away_loads_when_it_is_back(
        tmp_path: Path, sim: Any, basis: Any, browser: Any,  # noqa: F811 (the fixture)
) -> None:
    """A row clicked while the daemon was stopped kept the panel broken once it was back: the
    heading named the clicked job, the polar charts still showed the previous job's curves,
    and the rendering said "the daemon does not answer" under a live chip, until the row was
    clicked again (the page took the failed job's result as shown)."""
    import time

    from selenium.webdriver.common.by import By

    from tests.system.api.conftest import export_fits_off

    key = secrets.token_hex(24)
    data_dir = tmp_path / "data"
    first = _app(data_dir, sim, key, basis)
    with live_server(first) as url:
        daemon = Daemon(url, key, first, sim, data_dir)
        with export_fits_off(daemon), daemon.client() as c:
            ids = [c.post("/api/v1/jobs", params={"accept_uncalibrated": "true"}, json={
                "plan": {"kind": "uniform", "specimen": name, "rotations": 4,
                         "exposure": {"exposure_s": 0.005}}}).json()["id"] for name in "AB"]
            deadline = time.monotonic() + 180
            while any(c.get(f"/api/v1/jobs/{i}").json()["state"] != "completed" for i in ids):
                assert time.monotonic() < deadline, "the two scans did not complete"
                time.sleep(0.3)
        a, b = ids
        wait = open_live(browser, daemon, 90, poll_s=0.1)
        click_when_steady(wait, f'#jobs tr[data-id="{a}"]')
        wait.until(lambda d: f"job {a} reconstruction" in _polar_labels(d))
    port = int(url.rsplit(":", 1)[1])

    # Stopped: B's row clicked, its result cannot load. A's curves are not left under B's
    # heading.
    wait.until(_message)
    click_when_steady(wait, f'#jobs tr[data-id="{b}"]')
    wait.until(lambda d: f"job {b}" in d.find_element(By.ID, "result-job").text)
    wait.until(lambda d: f"job {a} reconstruction" not in _polar_labels(d))

    # Back: B's result loads by itself, no click needed.
    second = _app(data_dir, sim, key, basis)
    with live_server(second, port=port):
        wait.until(lambda d: d.find_element(By.ID, "live-chip").text == "live")
        wait.until(lambda d: f"job {b} reconstruction" in _polar_labels(d))
        wait.until(lambda d: "No rendering" not in d.find_element(By.ID, "render-caption").text
                   and d.find_element(By.ID, "render").is_displayed())
        assert f"job {a} reconstruction" not in _polar_labels(browser)
