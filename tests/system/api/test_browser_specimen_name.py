"""A scan started from the lab page without a specimen name, in headless Chromium: the page,
the job and the result's exports call it the same. A newcomer pressed Start scan with the form
as it came (its Specimen field prefilled "specimen"): the queue listed "specimen", and every
export of it said "unnamed" (``specimen_named`` false, a material named ``unnamed_job2``),
as exports read that placeholder (gonio.export.metadata)."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import pytest

from gonio.brdf.tables.table import BRDFTable
from tests.system.api.conftest import Daemon, export_fits_off
from tests.system.api.test_browser import browser, click_when_steady, open_live  # noqa: F401

pytestmark = [pytest.mark.system, pytest.mark.timeout(300)]


def test_an_unnamed_scan_is_unnamed_on_the_page_and_in_its_export(
        daemon: Daemon, browser: Any, tmp_path: Path,  # noqa: F811 (the fixture)
) -> None:
    from selenium.webdriver.common.by import By

    wait = open_live(browser, daemon, 60)
    form = browser.find_element(By.ID, "scan-form")
    field = form.find_element(By.NAME, "rotations")
    field.clear()
    field.send_keys("4")
    # The Specimen field as the page comes: nothing typed.
    with export_fits_off(daemon), daemon.client() as c:
        before = {j["id"] for j in c.get("/api/v1/jobs").json()}
        click_when_steady(wait, "#start-scan")
        deadline = time.monotonic() + 240
        while not (new := [j for j in c.get("/api/v1/jobs").json() if j["id"] not in before]):
            assert time.monotonic() < deadline, "the page started no job"
            time.sleep(0.2)
        job = new[0]
        while c.get(f"/api/v1/jobs/{job['id']}").json()["state"] != "completed":
            assert time.monotonic() < deadline, "the scan did not complete"
            time.sleep(0.2)
        # The export fits on demand (the scan finished without its fits): seconds of CPU,
        # more on a busy machine than the client's default 30 s.
        export = c.get(f"/api/v1/jobs/{job['id']}/export", params={"format": "table"},
                       timeout=240)
        assert export.status_code == 200, export.text
    path = tmp_path / "export.npz"
    path.write_bytes(export.content)
    meta = dict(BRDFTable.load(path).provenance)
    shown = browser.find_element(
        By.CSS_SELECTOR, f"#jobs tr[data-id='{job['id']}'] td:nth-child(2)").text
    # The export says unnamed and not named; the page and the job say the same name.
    assert meta.get("specimen") == "unnamed" and meta.get("specimen_named") is False, meta
    assert job["specimen"] == shown == meta["specimen"], (job["specimen"], shown)
