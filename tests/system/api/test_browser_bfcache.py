"""The lab page in a browser that keeps pages in its back/forward cache, as a lab's browser does:
a page left closes its event stream, and a page shown again from the cache opens it anew.

Found by the browser tests: each page a tab left stayed in the cache with its fetch of
/events open, and Chromium opens six connections to one host, so after six such pages the
seventh load waited about a minute for one to free. The count of open streams is the
daemon's own (``gonio_sse_subscribers`` in ``GET /metrics``)."""

from __future__ import annotations

import re
import time
from typing import Any

import pytest

from tests.system.api.conftest import Daemon
from tests.system.api.test_browser import open_live, start_chromium

pytestmark = pytest.mark.system


def _open_streams(daemon: Daemon) -> int:
    with daemon.client() as c:
        text = c.get("/metrics").text
    m = re.search(r"^gonio_sse_subscribers (\S+)$", text, re.MULTILINE)
    assert m is not None, text
    return int(float(m.group(1)))


def _until(what: str, check: Any, timeout_s: float = 60.0) -> None:
    """Wait for ``check()`` to hold: the daemon sees a closed stream when it next writes to it
    (a keep-alive), so not at once."""
    deadline = time.monotonic() + timeout_s
    while not check():
        assert time.monotonic() < deadline, what
        time.sleep(0.2)


def test_pages_left_for_the_back_forward_cache_close_their_event_streams(
        daemon: Daemon) -> None:
    browser = start_chromium(back_forward_cache=True)
    try:
        # More pages than the six connections Chromium opens to one host; each must go live
        # (open_live waits for it), which the seventh did not while the others held theirs.
        for _ in range(8):
            open_live(browser, daemon, 60)
        browser.execute_script("window.__keptInCache = true;")
        _until("the pages left still hold event streams",
               lambda: _open_streams(daemon) == 1)
        # Leave the page shown and come back to it: restored from the cache (its scripts'
        # state is still there), it follows the daemon's events again.
        browser.get("about:blank")
        _until("the page left still holds its event stream",
               lambda: _open_streams(daemon) == 0)
        browser.back()
        assert browser.execute_script("return window.__keptInCache === true;"), \
            "the page was loaded anew, not restored from the back/forward cache"
        _until("the restored page did not go live again", lambda: browser.execute_script(
            "return document.getElementById('live-chip').textContent;") == "live")
        _until("the restored page opened no event stream",
               lambda: _open_streams(daemon) == 1)
    finally:
        browser.quit()
