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
