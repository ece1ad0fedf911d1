"""Where a reconstruction whose basis cannot hold the readings is said (issue 23 item 4): the
headline error the CLI and the lab page show, and the record every export carries."""

from __future__ import annotations

from gonio.export.metadata import export_provenance
from gonio.figures import headline_error

WHY = "the readings carry structure the basis cannot hold: the reconstruction misses ..."
BOUNDS = "the reconstruction is outside physical bounds: ..."


def test_the_headline_error_says_the_basis_does_not_fit() -> None:
    plain = headline_error({"predicted_log_rmse": 0.25})
    flagged = headline_error({"predicted_log_rmse": 0.25, "basis_misfit": WHY})
    assert plain is not None and flagged is not None
    assert plain["text"] == "0.250" and "basis_misfit" not in plain
    assert flagged["text"] == "0.250 (BASIS MISFIT)"
    assert flagged["meaning"].startswith(f"Warning: {WHY}")
    assert flagged["basis_misfit"] == WHY
    assert headline_error({"basis_misfit": WHY}) is None  # no estimate: nothing to annotate
    both = headline_error({"predicted_log_rmse": 3.9, "basis_misfit": WHY,
                           "physical_bounds": BOUNDS})
    assert both is not None
    assert both["text"] == "3.900 (OUTSIDE PHYSICAL BOUNDS) (BASIS MISFIT)"
    assert WHY in both["meaning"] and BOUNDS in both["meaning"]


def test_every_export_lists_the_misfit_warning() -> None:
    out = export_provenance({"specimen": "tf"}, {}, {"basis_misfit": WHY}, {})
    assert WHY in out["warnings"]
