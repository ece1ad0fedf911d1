"""Where a reconstruction outside physical bounds is said (issue 23 item 4): the headline
error the CLI and the lab page show, and the record every export carries."""

from __future__ import annotations

from gonio.export.metadata import export_provenance
from gonio.figures import headline_error

WHY = "the reconstruction is outside physical bounds: its maximum 2.3e+13 is 3.1e+13 times ..."


def test_the_headline_error_leads_with_the_bounds_warning() -> None:
    plain = headline_error({"predicted_log_rmse": 3.87})
    flagged = headline_error({"predicted_log_rmse": 3.87, "physical_bounds": WHY})
    assert plain is not None and flagged is not None
    assert plain["text"] == "3.870" and "OUTSIDE" not in plain["meaning"]
    assert flagged["text"] == "3.870 (OUTSIDE PHYSICAL BOUNDS)"
    assert flagged["meaning"].startswith(f"Warning: {WHY}")
    assert flagged["physical_bounds"] == WHY
    assert headline_error({"physical_bounds": WHY}) is None  # no estimate: nothing to annotate


def test_every_export_lists_the_bounds_warning() -> None:
    out = export_provenance({"specimen": "al"}, {}, {"physical_bounds": WHY}, {})
    assert WHY in out["warnings"]
    assert export_provenance({"specimen": "al"}, {}, {}, {})["warnings"] == []


def test_the_headline_error_says_a_calibration_at_another_exposure() -> None:
    # The daemon's log and gonio scan read 'completed, in 1/sr: predicted_log_rmse 0.088'
    # for a scan 50 times off through a calibration at another exposure.
    off = "the calibration was measured at exposure 0.01 s, this scan at 0.5 s; ..."
    flagged = headline_error({"predicted_log_rmse": 0.088, "calibration_warning": off})
    assert flagged is not None
    assert flagged["text"] == "0.088 (CALIBRATED AT ANOTHER EXPOSURE)"
    assert flagged["meaning"].startswith(f"Warning: {off}")
    assert flagged["calibration_warning"] == off
