"""The lab page's colour table (headless Chromium): a spectral specimen scanned on the simulated
rig shows CIELAB at the instrument geometries beside its rendering, the numbers the API gives;
a comparison job adds CIEDE2000. The instrument menu starts on the rig's design instrument
(``[design] colour_instrument``) when the rig config has one, on MA98 when it has none.

One simulated rig and one pair of scans serve both tests: the daemon restarts on the same data
directory when the rig config gains its ``[design]`` table (``_SpectralLab``)."""

from __future__ import annotations

import csv
import io
import re
import secrets
from collections.abc import Iterator
from contextlib import ExitStack
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


class _SpectralLab:
    """One simulated spectral rig and its data directory, served by one daemon at a time.

    :meth:`serve` restarts the daemon when asked for another ``[design]`` table, as a lab
    restarts ``gonio serve`` after pasting the table ``gonio design --colour`` wrote into its
    rig config: the calibration, the jobs and their results stay in the data directory, so
    the scans are made once for every test of the module."""

    def __init__(self, tmp_path_factory: pytest.TempPathFactory, basis: Any) -> None:
        from gonio.sim.rig import DEFAULT_LIGHTS, DEFAULT_SENSORS, SimRigOptions, start_sim_rig
        from gonio.sim.spectral import CHIP_11, spectral_specimen

        self.basis = basis
        self.data_dir = tmp_path_factory.mktemp("gonio-data")
        theta_l, phi_l = DEFAULT_LIGHTS[0]
        assert theta_l == 45.0
        sensors = (*DEFAULT_SENSORS, (30.0, (phi_l + 180.0) % 360.0))
        # An 11-channel spectral sensor chip rather than the 31-band spectrometer
        # (tests/system/api/test_colour.py scans with that one): what the page shows does not
        # depend on the number of bands, and every request on a result reads all of them.
        self.sim = start_sim_rig(SimRigOptions(
            material=spectral_specimen("metallic-blue-paint", CHIP_11), time_scale=10.0,
            settle_s=0.0, sensors=sensors))
        self.design: dict[str, Any] | None = None
        self.daemon: Daemon | None = None
        self._serving = ExitStack()

    def serve(self, design: dict[str, Any] | None) -> Daemon:
        """The daemon whose rig config's ``[design]`` table is ``design`` (None: none),
        restarted on the same data directory when the one running has another."""
        from gonio.config import RigConfig

        if self.daemon is not None and design == self.design:
            return self.daemon
        self._serving.close()
        rig = self.sim.config
        if design is not None:
            # Validated as a rig config file's table is (the instrument's name made canonical).
            rig = RigConfig.model_validate({**rig.model_dump(), "design": design})
        key = secrets.token_hex(24)
        cfg = DaemonConfig().with_overrides(paths__data_dir=str(self.data_dir))
        app = build_app(cfg, rig, ApiKeyring({"tester": key}),
                        basis=BasisSupply(lambda: self.basis))
        app.state.service.worker.fit_exports = False  # the spectral fits are not under test
        url = self._serving.enter_context(live_server(app))
        self.design, self.daemon = design, Daemon(url, key, app, self.sim, self.data_dir)
        return self.daemon

    def close(self) -> None:
        try:
            self._serving.close()
        finally:
            self.sim.close()


@pytest.fixture(scope="module")
def spectral_lab(tmp_path_factory: pytest.TempPathFactory, basis: Any) -> Iterator[_SpectralLab]:
    """The spectral rig: a spectral specimen read by spectral sensors.

    Besides the default devices, a fifth sensor at 30 degrees in the plane of the first light
    (45 degrees), on the far side: that pair sits at the instruments' 45as15 geometry
    (aspecular 15: the sensor 15 degrees from the specular direction, toward the light)."""
    lab = _SpectralLab(tmp_path_factory, basis)
    try:
        yield lab
    finally:
        lab.close()


@pytest.fixture(scope="module")
def spectral_jobs(spectral_lab: _SpectralLab) -> list[int]:
    """Two completed scans of the blue panel, calibrated against the white reference, made
    once (by the daemon without a ``[design]`` table) for every test of the module."""
    d = spectral_lab.serve(None)
    _calibrate(d)
    with d.client() as c:
        ids = [c.post("/api/v1/jobs", json=scan(name, rotations=4)).json()["id"]
               for name in ("blue panel", "blue panel, batch 2")]
        for job_id in ids:
            assert wait_state(c, job_id, {"completed", "failed"}, 240)["state"] == "completed"
    return ids


def _serve(lab: _SpectralLab, design: dict[str, Any] | None, browser: Any) -> Daemon:  # noqa: F811
    """``lab``'s daemon with ``design``, the browser on a blank page meanwhile: a page left
    open on a daemon that restarts logs its refused requests, which are not the next test's."""
    browser.get("about:blank")
    d = lab.serve(design)
    browser.get_log("browser")
    return d


@pytest.fixture
def spectral_daemon(spectral_lab: _SpectralLab, spectral_jobs: list[int],
                    browser: Any) -> Daemon:  # noqa: F811
    """The spectral rig without a ``[design]`` table."""
    return _serve(spectral_lab, None, browser)


@pytest.fixture
def byk_design_daemon(spectral_lab: _SpectralLab, spectral_jobs: list[int],
                      browser: Any) -> Daemon:  # noqa: F811
    """The spectral rig whose ``[design]`` was made for the BYK-mac (``gonio design --colour
    BYK-mac``), its name written as a user might (the config makes it canonical)."""
    design = {"rotations": 8, "pairs": 10, "colour_instrument": "byk mac", "colour_weight": 10.0}
    return _serve(spectral_lab, design, browser)


def test_colour_table_beside_the_rendering(spectral_daemon: Daemon, spectral_jobs: list[int],
                                           browser: Any) -> None:  # noqa: F811
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import Select

    d, ids = spectral_daemon, spectral_jobs
    with d.client() as c:
        api = c.get(f"/api/v1/jobs/{ids[1]}/colour", params={"instrument": "MA98"}).json()
        api_csv = c.get(f"/api/v1/jobs/{ids[1]}/colour",
                        params={"instrument": "MA98", "format": "csv"}).text
    assert api["colour"]["space"] == "CIELAB"
    # The one pair placed at 45as15 read that geometry; every other row is the table's. The
    # JSON's flags and the CSV's column say so.
    names = [f"{r['incidence_deg']:g}as{r['aspecular_deg']:g}" for r in api["colour"]["rows"]]
    assert [n for n, m in zip(names, api["colour"]["measured"], strict=True) if m] == ["45as15"]
    csv_rows = list(csv.DictReader(io.StringIO(api_csv)))
    assert [r["source"] for r in csv_rows] == [
        "pair" if n == "45as15" else "table" for n in names]
    # The near-specular geometries the pair did not read (MA98's within 25 degrees of the
    # specular direction, from its published aspecular angles) are noted, and the page says so.
    (note,) = api["notes"]
    assert note.startswith("the geometries within 25 degrees of the specular direction "
                           "(45as-15, 45as25, 15as-15, 15as-5) were read from the "
                           "reconstructed table"), note
    # The page opens on the newest job (the second scan), which the test reads first: no
    # click, and no other job's views computed; the first scan is the one compared with.
    wait = open_live(browser, d, 240)
    wait.until(lambda b: b.find_element(By.ID, "result-job").text.startswith(f"job {ids[1]} ")
               and b.find_element(By.ID, "colour").is_displayed()
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
    assert ("Note: the geometries within 25 degrees of the specular direction (45as-15, "
            "45as25, 15as-15, 15as-5) were read from the reconstructed table") in caption, caption
    # Another instrument, then a comparison: ΔE00 appears as a column.
    Select(browser.find_element(By.ID, "colour-instrument")).select_by_value("BYK-mac")
    wait.until(lambda b: "BYK-mac geometries" in b.find_element(By.ID, "colour-caption").text)
    assert len(browser.find_elements(By.CSS_SELECTOR, "#colour-table tbody tr")) == 6
    wait.until(lambda b: str(ids[0]) in [o.get_attribute("value") for o in
                                         b.find_elements(By.CSS_SELECTOR, "#compare option")])
    Select(browser.find_element(By.ID, "compare")).select_by_value(str(ids[0]))
    wait.until(lambda b: f"against job {ids[0]}" in b.find_element(By.ID, "colour-caption").text)
    head = [th.text for th in browser.find_elements(By.CSS_SELECTOR, "#colour-table thead th")]
    assert head[-2:] == ["source", "ΔE00"]
    # The caption quotes the instrument's maximum and mean ΔE00 (it gave the maximum alone),
    # both of the API's per-geometry values: the BYK-mac's six geometries, each once.
    with d.client() as c:
        rows = c.get(f"/api/v1/jobs/{ids[1]}/colour", params={
            "instrument": "BYK-mac", "against": str(ids[0])}).json()["difference"]["rows"]
    per_geometry = {(r["incidence_deg"], r["aspecular_deg"], r["azimuth_deg"]): r["dE00"]
                    for r in rows}
    assert len(per_geometry) == 6, rows
    shown = re.search(r"max ([0-9.]+), mean ([0-9.]+)",
                      browser.find_element(By.ID, "colour-caption").text)
    assert shown is not None, browser.find_element(By.ID, "colour-caption").text
    assert float(shown.group(1)) == pytest.approx(max(per_geometry.values()), abs=0.006)
    assert float(shown.group(2)) == pytest.approx(
        sum(per_geometry.values()) / len(per_geometry), abs=0.006)
    assert not _severe(browser)


def test_instrument_menu_starts_on_the_rig_design_instrument(
        byk_design_daemon: Daemon, spectral_jobs: list[int], browser: Any) -> None:  # noqa: F811
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import Select

    d, ids = byk_design_daemon, spectral_jobs
    with d.client() as c:
        # What the page reads: the rig config's [design] table, the name made canonical.
        assert c.get("/api/v1/rig/config").json()["design"]["colour_instrument"] == "BYK-mac"
        api = c.get(f"/api/v1/jobs/{ids[1]}/colour", params={"instrument": "BYK-mac"}).json()
    # The BYK-mac's six geometries (45as-15 ... 45as110; docs/colour.md), independent of gonio.
    byk = ["45as-15", "45as15", "45as25", "45as45", "45as75", "45as110"]
    # The page opens on the newest job (the second scan); then the first is chosen.
    wait = open_live(browser, d, 240)
    wait.until(lambda b: b.find_element(By.ID, "result-job").text.startswith(f"job {ids[1]} ")
               and "BYK-mac geometries" in b.find_element(By.ID, "colour-caption").text)
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
    click_when_steady(wait, f'#jobs tr[data-id="{ids[0]}"]')
    wait.until(lambda b: b.find_element(By.ID, "result-job").text.startswith(f"job {ids[0]} ")
               and "MA98 geometries" in b.find_element(By.ID, "colour-caption").text)
    assert Select(browser.find_element(By.ID, "colour-instrument")).first_selected_option \
        .get_attribute("value") == "MA98"
    assert len(browser.find_elements(By.CSS_SELECTOR, "#colour-table tbody tr")) == 11
    assert not _severe(browser)


def test_a_result_saved_as_a_standard_is_compared_with_by_name_on_the_page(
        spectral_daemon: Daemon, spectral_jobs: list[int], browser: Any) -> None:  # noqa: F811
    """The colour panel saves the table shown as a stored standard (PUT
    /api/v1/colour-standards/NAME) and compares any result with a stored standard chosen by
    name; a lab's standards were files it copied into the data directory by hand."""
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import Select

    d, ids = spectral_daemon, spectral_jobs
    with d.client() as c:
        # The differences the page must show: the API's own, against the first panel's job.
        by_job = c.get(f"/api/v1/jobs/{ids[1]}/colour",
                       params={"instrument": "MA98", "against": ids[0]}).json()["difference"]
    wait = open_live(browser, d, 240)
    click_when_steady(wait, f'#jobs tr[data-id="{ids[0]}"]')
    wait.until(lambda b: b.find_element(By.ID, "result-job").text.startswith(f"job {ids[0]} ")
               and "MA98 geometries" in b.find_element(By.ID, "colour-caption").text)
    # Nameless: not sent, the field asks for a name.
    click_when_steady(wait, "#colour-save-standard")
    wait.until(lambda b: "Name the standard first" in
               b.find_element(By.ID, "colour-standard-state").text)
    browser.find_element(By.ID, "colour-standard-name").send_keys("page master")
    click_when_steady(wait, "#colour-save-standard")
    wait.until(lambda b: "standard page master" in
               b.find_element(By.ID, "colour-standard-state").text)
    assert browser.find_element(By.ID, "colour-standard-state").text.startswith(
        ("Saved standard page master: job", "Replaced standard page master: job"))
    assert (d.data_dir / "standards" / "page master.csv").is_file()
    # The second panel against it, by name: the same ΔE00 as against the first job itself,
    # up to the CSV's rounding of L*, a*, b*.
    click_when_steady(wait, f'#jobs tr[data-id="{ids[1]}"]')
    wait.until(lambda b: "page master" in [o.get_attribute("value") for o in b.find_elements(
        By.CSS_SELECTOR, "#colour-standard option")])
    Select(browser.find_element(By.ID, "colour-standard")).select_by_value("page master")
    wait.until(lambda b: b.find_element(By.ID, "result-job").text.startswith(f"job {ids[1]} ")
               and "against standard page master" in
               b.find_element(By.ID, "colour-caption").text)
    head = [th.text for th in browser.find_elements(By.CSS_SELECTOR, "#colour-table thead th")]
    assert head[-1] == "ΔE00"
    shown = [float(tr.find_elements(By.TAG_NAME, "td")[-1].text)
             for tr in browser.find_elements(By.CSS_SELECTOR, "#colour-table tbody tr")]
    assert shown == pytest.approx([r["dE00"] for r in by_job["rows"]], abs=0.011)
    # The table shown, downloaded as gonio colour --csv writes it (the API has had it),
    # named after the job and its specimen as the result and the exports are.
    click_when_steady(wait, "#colour-csv")
    wait.until(lambda b: b.find_element(By.ID, "colour-standard-state").text
               == f"saved gonio-job-{ids[1]}-blue-panel-batch-2-colour-MA98.csv")
    assert not _severe(browser)


def test_a_stored_standard_is_deleted_from_the_page_after_asking(
        spectral_daemon: Daemon, spectral_jobs: list[int], browser: Any) -> None:  # noqa: F811
    """The colour panel lists the stored standards but could not remove one: "Delete
    standard" removes the one chosen (DELETE /api/v1/colour-standards/NAME) once the user
    confirms; dismissed, it stays."""
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support import expected_conditions as ec
    from selenium.webdriver.support.ui import Select

    d, ids = spectral_daemon, spectral_jobs
    stored = d.data_dir / "standards" / "to remove.csv"
    with d.client() as c:
        table = c.get(f"/api/v1/jobs/{ids[0]}/colour", params={"instrument": "MA98",
                                                              "format": "csv"}).text
        put = c.put("/api/v1/colour-standards/to remove", content=table,
                    headers={"Content-Type": "text/csv"})
        assert put.status_code == 200, put.text
    wait = open_live(browser, d, 240)
    wait.until(lambda b: b.find_element(By.ID, "result-job").text.startswith(f"job {ids[1]} ")
               and "CIELAB" in b.find_element(By.ID, "colour-caption").text)
    button = browser.find_element(By.ID, "colour-delete-standard")
    assert not button.is_enabled()  # no standard chosen: nothing to delete
    # The menu's options are replaced as the list changes: read in one script call.
    def listed(b: Any) -> list[str]:
        return list(b.execute_script(
            "return [...document.querySelectorAll('#colour-standard option')].map(o => o.value)"))

    wait.until(lambda b: "to remove" in listed(b))
    Select(browser.find_element(By.ID, "colour-standard")).select_by_value("to remove")
    wait.until(lambda b: "against standard to remove" in
               b.find_element(By.ID, "colour-caption").text)
    assert button.is_enabled()
    click_when_steady(wait, "#colour-delete-standard")
    alert = wait.until(ec.alert_is_present())
    assert "Delete the stored standard to remove?" in alert.text, alert.text
    assert "for every client" in alert.text
    alert.dismiss()
    assert stored.is_file()
    click_when_steady(wait, "#colour-delete-standard")
    wait.until(ec.alert_is_present()).accept()
    wait.until(lambda b: b.find_element(By.ID, "colour-standard-state").text
               == "Deleted standard to remove.")
    assert not stored.exists()
    # Gone from the menu; the table is this job's alone again, without a ΔE00 column.
    wait.until(lambda b: "to remove" not in listed(b))
    wait.until(lambda b: "against standard" not in b.find_element(By.ID, "colour-caption").text)
    assert Select(browser.find_element(By.ID, "colour-standard")) \
        .first_selected_option.get_attribute("value") == ""
    assert not browser.find_element(By.ID, "colour-delete-standard").is_enabled()
    assert not _severe(browser)


def test_a_standard_of_another_instrument_is_compared_at_its_angles_row_by_row(
        spectral_daemon: Daemon, spectral_jobs: list[int], browser: Any) -> None:  # noqa: F811
    """A standard measured at MA68's five geometries against a result shown at MA98's eleven:
    the five shared angles get their ΔE00 on their own rows (the column was filled by
    position, which put 45as15's difference on 45as-15's row), the other six none, and the
    caption says the instruments differ."""
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import Select

    d, ids = spectral_daemon, spectral_jobs
    with d.client() as c:
        table = c.get(f"/api/v1/jobs/{ids[0]}/colour", params={"instrument": "MA68",
                                                              "format": "csv"}).text
        put = c.put("/api/v1/colour-standards/ma68 master", content=table,
                    headers={"Content-Type": "text/csv"})
        assert put.status_code == 200, put.text
        body = c.get(f"/api/v1/jobs/{ids[1]}/colour",
                     params={"instrument": "MA98", "against": "ma68 master"}).json()
    # What the API says, from the instruments' published angles: MA68's five are MA98's
    # 45 degree geometries from 15 to 110 aspecular.
    want = {f"{r['incidence_deg']:g}as{r['aspecular_deg']:g}": r["dE00"]
            for r in body["difference"]["rows"]}
    assert sorted(want) == sorted(["45as15", "45as25", "45as45", "45as75", "45as110"])
    assert any("MA68" in n for n in body["notes"])
    wait = open_live(browser, d, 240)
    click_when_steady(wait, f'#jobs tr[data-id="{ids[1]}"]')
    Select(browser.find_element(By.ID, "colour-instrument")).select_by_value("MA98")
    wait.until(lambda b: "ma68 master" in [o.get_attribute("value") for o in b.find_elements(
        By.CSS_SELECTOR, "#colour-standard option")])
    Select(browser.find_element(By.ID, "colour-standard")).select_by_value("ma68 master")
    wait.until(lambda b: "against standard ma68 master" in
               b.find_element(By.ID, "colour-caption").text)
    shown = {}
    for tr in browser.find_elements(By.CSS_SELECTOR, "#colour-table tbody tr"):
        cells = [td.text for td in tr.find_elements(By.TAG_NAME, "td")]
        shown[cells[0]] = cells[-1]
    assert len(shown) == 11
    for name, cell in shown.items():
        if name in want:
            assert float(cell) == pytest.approx(want[name], abs=0.006), name
        else:
            assert cell == "–", name
    assert "MA68" in browser.find_element(By.ID, "colour-caption").text
    assert not _severe(browser)
