"""The lab page's colour table (headless Chromium): a spectral specimen scanned on the simulated
rig shows CIELAB at the instrument geometries beside its rendering, the numbers the API gives;
a comparison job adds CIEDE2000. The instrument menu starts on the rig's design instrument
(``[design] colour_instrument``) when the rig config has one, on MA98 when it has none."""

from __future__ import annotations

import csv
import io
import secrets
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import pytest

from gonio.api.auth import ApiKeyring
from gonio.basis_supply import BasisSupply
from gonio.daemon import DaemonConfig, build_app
from tests.system.api.conftest import Daemon
from tests.system.api.live_server import live_server
from tests.system.api.test_browser import (  # noqa: F401
    _calibrate,
    _severe,
    browser,
    click_when_steady,
    open_live,
)
from tests.system.api.test_scan_flow import scan, wait_state

pytestmark = pytest.mark.system


@contextmanager
def _spectral_daemon(tmp_path_factory: pytest.TempPathFactory, basis: Any,
                     design: dict[str, Any] | None = None) -> Iterator[Daemon]:
    """A daemon of its own whose simulated rig holds a spectral specimen (31-band sensors);
    ``design``, when given, is the rig config's ``[design]`` table.

    Besides the default devices, a fifth sensor at 30 degrees in the plane of the first light
    (45 degrees), on the far side: that pair sits at the instruments' 45as15 geometry
    (aspecular 15: the sensor 15 degrees from the specular direction, toward the light)."""
    from gonio.config import RigConfig
    from gonio.sim.rig import DEFAULT_LIGHTS, DEFAULT_SENSORS, SimRigOptions, start_sim_rig

    data_dir = tmp_path_factory.mktemp("gonio-data")
    theta_l, phi_l = DEFAULT_LIGHTS[0]
    assert theta_l == 45.0
    sensors = (*DEFAULT_SENSORS, (30.0, (phi_l + 180.0) % 360.0))
    sim = start_sim_rig(SimRigOptions(material="metallic-blue-paint", time_scale=10.0,
                                      settle_s=0.0, sensors=sensors))
    rig = sim.config
    if design is not None:
        # Validated as a rig config file's table is (the instrument's name made canonical).
        rig = RigConfig.model_validate({**rig.model_dump(), "design": design})
    key = secrets.token_hex(24)
    cfg = DaemonConfig().with_overrides(paths__data_dir=str(data_dir))
    app = build_app(cfg, rig, ApiKeyring({"tester": key}), basis=BasisSupply(lambda: basis))
    app.state.service.worker.fit_exports = False  # 31-channel fits are not under test
    try:
        with live_server(app) as url:
            yield Daemon(url, key, app, sim, data_dir)
    finally:
        sim.close()


@pytest.fixture(scope="module")
def spectral_daemon(tmp_path_factory: pytest.TempPathFactory, basis: Any) -> Iterator[Daemon]:
    """The spectral rig without a ``[design]`` table."""
    with _spectral_daemon(tmp_path_factory, basis) as d:
        yield d


@pytest.fixture(scope="module")
def byk_design_daemon(tmp_path_factory: pytest.TempPathFactory, basis: Any) -> Iterator[Daemon]:
    """The spectral rig whose ``[design]`` was made for the BYK-mac (``gonio design --colour
    BYK-mac``), its name written as a user might (the config makes it canonical)."""
    design = {"rotations": 8, "pairs": 10, "colour_instrument": "byk mac", "colour_weight": 10.0}
    with _spectral_daemon(tmp_path_factory, basis, design) as d:
        yield d


def test_colour_table_beside_the_rendering(spectral_daemon: Daemon,
                                           browser: Any) -> None:  # noqa: F811
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import Select

    d = spectral_daemon
    _calibrate(d)
    with d.client() as c:
        ids = [c.post("/api/v1/jobs", json=scan(name, rotations=4)).json()["id"]
               for name in ("blue panel", "blue panel, batch 2")]
        for job_id in ids:
            assert wait_state(c, job_id, {"completed", "failed"}, 240)["state"] == "completed"
        api = c.get(f"/api/v1/jobs/{ids[0]}/colour", params={"instrument": "MA98"}).json()
        api_csv = c.get(f"/api/v1/jobs/{ids[0]}/colour",
                        params={"instrument": "MA98", "format": "csv"}).text
    assert api["colour"]["space"] == "CIELAB"
    # The one pair placed at 45as15 read that geometry; every other row is the table's. The
    # JSON's flags and the CSV's column say so.
    names = [f"{r['incidence_deg']:g}as{r['aspecular_deg']:g}" for r in api["colour"]["rows"]]
    assert [n for n, m in zip(names, api["colour"]["measured"], strict=True) if m] == ["45as15"]
    csv_rows = list(csv.DictReader(io.StringIO(api_csv)))
    assert [r["source"] for r in csv_rows] == [
        "pair" if n == "45as15" else "table" for n in names]
    wait = open_live(browser, d, 240)
    row = f'#jobs tr[data-id="{ids[0]}"]'
    click_when_steady(wait, row)
    wait.until(lambda b: b.find_element(By.ID, "colour").is_displayed()
               and "CIELAB" in b.find_element(By.ID, "colour-caption").text)
    caption = browser.find_element(By.ID, "colour-caption").text
    assert "D65/10°" in caption and "MA98 geometries" in caption and "flop index" in caption
    # No [design] table: the menu stays on its first instrument, none marked as the rig's.
    menu = Select(browser.find_element(By.ID, "colour-instrument"))
    assert menu.first_selected_option.get_attribute("value") == "MA98"
    assert not any("rig design" in o.text for o in menu.options)
    cells = [[td.text for td in tr.find_elements(By.TAG_NAME, "td")]
             for tr in browser.find_elements(By.CSS_SELECTOR, "#colour-table tbody tr")]
    assert len(cells) == 11 and cells[0][0] == "45as-15"
    # The page shows the API's numbers, and beside them where each row came from.
    first = api["colour"]["rows"][0]
    assert cells[0][1:4] == [f"{first[k]:.2f}" for k in ("L", "a", "b")]
    head = [th.text for th in browser.find_elements(By.CSS_SELECTOR, "#colour-table thead th")]
    assert head[-1] == "source"
    assert {c[0]: c[-1] for c in cells} == {n: "pair" if n == "45as15" else "table"
                                           for n in names}
    assert "1 of 11 geometries read directly by a pair" in caption
    # Another instrument, then a comparison: ΔE00 appears as a column.
    Select(browser.find_element(By.ID, "colour-instrument")).select_by_value("BYK-mac")
    wait.until(lambda b: "BYK-mac geometries" in b.find_element(By.ID, "colour-caption").text)
    assert len(browser.find_elements(By.CSS_SELECTOR, "#colour-table tbody tr")) == 6
    wait.until(lambda b: str(ids[1]) in [o.get_attribute("value") for o in
                                         b.find_elements(By.CSS_SELECTOR, "#compare option")])
    Select(browser.find_element(By.ID, "compare")).select_by_value(str(ids[1]))
    wait.until(lambda b: f"against job {ids[1]}" in b.find_element(By.ID, "colour-caption").text)
    head = [th.text for th in browser.find_elements(By.CSS_SELECTOR, "#colour-table thead th")]
    assert head[-2:] == ["source", "ΔE00"]
    assert not _severe(browser)


def test_instrument_menu_starts_on_the_rig_design_instrument(byk_design_daemon: Daemon,
                                                             browser: Any) -> None:  # noqa: F811
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import Select

    d = byk_design_daemon
    _calibrate(d)
    with d.client() as c:
        # What the page reads: the rig config's [design] table, the name made canonical.
        assert c.get("/api/v1/rig/config").json()["design"]["colour_instrument"] == "BYK-mac"
        ids = [c.post("/api/v1/jobs", json=scan(name, rotations=4)).json()["id"]
               for name in ("blue panel", "blue panel, batch 2")]
        for job_id in ids:
            assert wait_state(c, job_id, {"completed", "failed"}, 240)["state"] == "completed"
        api = c.get(f"/api/v1/jobs/{ids[0]}/colour", params={"instrument": "BYK-mac"}).json()
    # The BYK-mac's six geometries (45as-15 ... 45as110; docs/colour.md), independent of gonio.
    byk = ["45as-15", "45as15", "45as25", "45as45", "45as75", "45as110"]
    wait = open_live(browser, d, 240)
    click_when_steady(wait, f'#jobs tr[data-id="{ids[0]}"]')
    wait.until(lambda b: "BYK-mac geometries" in b.find_element(By.ID, "colour-caption").text)
    menu = Select(browser.find_element(By.ID, "colour-instrument"))
    assert menu.first_selected_option.get_attribute("value") == "BYK-mac"
    assert menu.first_selected_option.text == "BYK-mac (rig design)"
    cells = [[td.text for td in tr.find_elements(By.TAG_NAME, "td")]
             for tr in browser.find_elements(By.CSS_SELECTOR, "#colour-table tbody tr")]
    assert [c[0] for c in cells] == byk
    first = api["colour"]["rows"][0]
    assert cells[0][1:4] == [f"{first[k]:.2f}" for k in ("L", "a", "b")]
    # The user's choice holds: another instrument, then another job, stays on it.
    menu.select_by_value("MA98")
    wait.until(lambda b: "MA98 geometries" in b.find_element(By.ID, "colour-caption").text)
    click_when_steady(wait, f'#jobs tr[data-id="{ids[1]}"]')
    wait.until(lambda b: b.find_element(By.ID, "result-job").text.startswith(f"job {ids[1]} ")
               and "MA98 geometries" in b.find_element(By.ID, "colour-caption").text)
    assert Select(browser.find_element(By.ID, "colour-instrument")).first_selected_option \
        .get_attribute("value") == "MA98"
    assert len(browser.find_elements(By.CSS_SELECTOR, "#colour-table tbody tr")) == 11
    assert not _severe(browser)
