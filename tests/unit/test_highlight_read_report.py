"""Where a result whose highlight no reading comes near is said (issue 23 item 4): the headline
error the CLI and the lab page show, the colour reports and the record every export carries."""

from __future__ import annotations

from gonio.export.metadata import RECONSTRUCTION_WARNINGS, export_provenance
from gonio.figures import headline_error

WHY = "the highlight is not read: the reconstruction peaks 4.48 times above ..."
MISFIT = "the readings carry structure the basis cannot hold: ..."


def test_the_headline_error_says_the_highlight_is_not_read() -> None:
    plain = headline_error({"predicted_log_rmse": 0.071, "highlight_excess": 1.1})
    flagged = headline_error({"predicted_log_rmse": 0.071, "highlight_excess": 4.48,
                              "highlight_not_read": WHY})
    assert plain is not None and flagged is not None
    assert plain["text"] == "0.071" and "highlight_not_read" not in plain
    assert flagged["text"] == "0.071 (HIGHLIGHT NOT READ)"
    assert flagged["meaning"].startswith(f"Warning: {WHY}")
    assert flagged["highlight_not_read"] == WHY
    assert headline_error({"highlight_not_read": WHY}) is None  # no estimate: nothing to annotate
    both = headline_error({"predicted_log_rmse": 0.3, "basis_misfit": MISFIT,
                           "highlight_not_read": WHY})
    assert both is not None and both["text"] == "0.300 (BASIS MISFIT) (HIGHLIGHT NOT READ)"
    assert WHY in both["meaning"] and MISFIT in both["meaning"]


def test_every_export_lists_the_warning() -> None:
    assert "highlight_not_read" in RECONSTRUCTION_WARNINGS
    out = export_provenance({"specimen": "red"}, {}, {"highlight_not_read": WHY}, {})
    assert WHY in out["warnings"] and WHY in out["reconstruction_warnings"]
