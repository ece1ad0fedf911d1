"""A calibration of other sensors (factors with another number of channels than the rig's
sensors read) is said by the dry run before anything is submitted: the API's dry run, ``gonio
scan --daemon URL --dry-run`` and the lab page's Check plan carry the refusal submission
answers (one decision: GonioService.channel_refusal). They said nothing, and the lab learned it
only when Start was refused. A real daemon on the simulated rig (conftest.py); the calibration
file in its data directory is replaced by one measured with 31-band sensors of the same names,
as a data directory shared with a spectral rig would hold."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from gonio.calibration import CALIBRATION_FILE, Calibration, PairCalibration, save_calibration
from gonio.cli import main
from tests.system.api.conftest import Daemon
from tests.system.api.test_browser import browser, check_plan, open_live  # noqa: F401

pytestmark = pytest.mark.system

BANDS = 31
"""Channels of the other sensors' factors (the simulated rig's sensors read 3: RGB)."""


@pytest.fixture
def other_sensors(daemon: Daemon) -> Iterator[int]:
    """The daemon's calibration in effect: factors for every pair with :data:`BANDS`
    channels. Yields the channels the rig's sensors read (from its description)."""
    desc = daemon.app.state.service.desc
    read = {len(s.channels) for s in desc.sensors}
    assert read == {3}, read  # the factors below must differ from every sensor's count
    cal = Calibration(pairs=tuple(PairCalibration(light=p.light, sensor=p.sensor,
                                                  factor=(1e-4,) * BANDS) for p in desc.pairs),
                      exposure_s=0.01, source="job 9: spectral white reference")
    path = Path(daemon.data_dir) / CALIBRATION_FILE
    assert not path.exists()
    save_calibration(cal, path)
    try:
        yield 3
    finally:
        path.unlink()


PLAN = {"kind": "uniform", "rotations": 4, "exposure": {"exposure_s": 0.01}}


def _channel_warnings(answer: dict[str, Any]) -> list[str]:
    return [w for w in answer["warnings"] if "other sensors" in w]


def test_the_dry_run_warns_with_the_refusal_submission_answers(
        daemon: Daemon, other_sensors: int) -> None:
    with daemon.client() as c:
        r = c.post("/api/v1/jobs/dry-run", json={"plan": PLAN})
        assert r.status_code == 200, r.text
        (warning,) = _channel_warnings(r.json())
        # "not calibrated:": the prefix the page reads as "Start would be refused".
        assert warning.startswith("not calibrated: the calibration in effect (job 9: "
                                  "spectral white reference) was measured with other sensors"), \
            warning
        assert f"have {BANDS} channels" in warning and f"reads {other_sensors}" in warning
        before = len(c.get("/api/v1/jobs").json())
        r = c.post("/api/v1/jobs", json={"plan": PLAN})
        assert r.status_code == 422, r.text
        assert warning == f"not calibrated: {r.json()['detail']}"  # the same finding
        assert len(c.get("/api/v1/jobs").json()) == before

        # A calibration job queued first calibrates these sensors: submission takes the scan
        # behind it, and the dry run says nothing of it either.
        assert c.post("/api/v1/rig/halt").status_code == 200
        try:
            cal = c.post("/api/v1/jobs", json={"plan": {
                "kind": "calibration", "rotations": 2, "reference_albedo": 0.99}})
            assert cal.status_code == 201, cal.text
            r = c.post("/api/v1/jobs/dry-run", json={"plan": PLAN})
            assert r.status_code == 200 and _channel_warnings(r.json()) == [], r.text
            assert c.post(f"/api/v1/jobs/{cal.json()['id']}/cancel").status_code == 200
        finally:
            assert c.post("/api/v1/rig/release").status_code == 200
        r = c.post("/api/v1/jobs/dry-run", json={"plan": PLAN})
        assert len(_channel_warnings(r.json())) == 1, r.text


def test_gonio_scan_dry_run_through_the_daemon_prints_it(
        daemon: Daemon, other_sensors: int, tmp_path: Path,
        capsys: pytest.CaptureFixture[str]) -> None:
    argv = ["scan", "--daemon", daemon.url, "--api-key", daemon.key, "--rotations", "4",
            "--exposure", "0.01", "--dry-run", "-o", str(tmp_path / "x.h5")]
    assert main(argv) == 0
    out = capsys.readouterr().out
    lines = [line for line in out.splitlines() if "other sensors" in line]
    assert len(lines) == 1, out
    assert lines[0].startswith("  warning: not calibrated: the calibration in effect"), out
    assert f"have {BANDS} channels" in lines[0] and "Calibrate this rig again" in lines[0], out


def test_check_plan_on_the_page_says_start_would_be_refused(
        daemon: Daemon, other_sensors: int, browser: Any,  # noqa: F811 (the fixture)
) -> None:
    from selenium.webdriver.common.by import By

    wait = open_live(browser, daemon, 60)
    note = check_plan(browser, wait, (("rotations", 4), ("exposure_s", 0.01)))
    assert note.startswith("Start would be refused: read the warning below"), note
    items = [li.text for li in browser.find_elements(By.CSS_SELECTOR, "#dry-run-warnings li")]
    said = [w for w in items if "other sensors" in w]
    assert len(said) == 1, items
    assert f"have {BANDS} channels" in said[0] and "Calibrate this rig again" in said[0], said
