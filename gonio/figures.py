"""Renderings of result files: the reconstruction, the true material when it is known, and
comparisons of several results (``gonio render``, ``GET /api/v1/jobs/{id}/render.png``).

The pictures themselves come from :mod:`gonio.brdf.render`; this module knows where the BRDFs
are in a result file. A result measured on the simulated rig carries the simulated material
in its provenance (``true_material``, written by :func:`describe_material`), so its rendering
shows the truth beside the reconstruction, as V&F's Fig. 9 shows reference and reconstruction.
"""

from __future__ import annotations

import json
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from gonio.brdf import models as bm
from gonio.brdf import render
from gonio.brdf.table import BRDFTable
from gonio.results import ResultFile, read_result

TRUE_MATERIAL_KEY = "true_material"
"""Provenance attribute of a result file: JSON of :func:`describe_material` (simulated rigs)."""


class FigureError(ValueError):
    """An input cannot be rendered; the message says which and why."""


def describe_material(brdf: Any) -> dict[str, Any] | None:
    """JSON-ready recipe of a simulated specimen, or None if it cannot be written down.

    Analytic models are stored whole (:func:`gonio.brdf.models.to_dict`); a table is stored
    by the file it came from, when its provenance names one.
    """
    if isinstance(brdf, BRDFTable):
        src = brdf.provenance.get("file") or brdf.provenance.get("path")
        return {"name": brdf.name, "table_file": str(src)} if src else None
    try:
        data = bm.to_dict(brdf)
    except Exception:  # an object that is not a model dataclass: nothing to record
        return None
    if not isinstance(data, dict) or "type" not in data:
        return None
    return {"name": str(getattr(brdf, "name", data["type"])), "model": data}


def material_from_description(desc: dict[str, Any]) -> Any:
    """Rebuild what :func:`describe_material` wrote; raises :class:`FigureError`."""
    try:
        if "model" in desc:
            return bm.from_dict(desc["model"])
        if "table_file" in desc:
            return BRDFTable.load(desc["table_file"])
    except (ValueError, OSError) as exc:
        raise FigureError(f"the true material {desc.get('name')!r} cannot be rebuilt: {exc}"
                          ) from None
    raise FigureError(f"true material description has neither a model nor a table: {desc}")


def true_material(res: ResultFile) -> Any | None:
    """The simulated material of a result, if recorded and the result is calibrated (1/sr)."""
    text = res.provenance.get(TRUE_MATERIAL_KEY)
    if not text:
        return None
    if not res.samples.calibration.get("pairs"):
        return None  # sensor units: the truth (1/sr) would not be on the same scale
    try:
        return material_from_description(json.loads(text))
    except (FigureError, json.JSONDecodeError):
        return None


def load_input(path: str | os.PathLike[str], label: str | None = None,
               with_truth: bool = True) -> list[tuple[str, Any]]:
    """Figure rows for one input: a result file (``.h5``) or a BRDF table (``.npz``).

    A result gives its reconstruction and, with ``with_truth``, the true material before it
    when known. Raises :class:`FigureError` for a file without a BRDF.
    """
    p = Path(path)
    if p.suffix.lower() == ".npz":
        table = BRDFTable.load(p)
        return [(label or f"{p.name}: {table.name}", table)]
    res = read_result(p)
    if res.table is None:
        raise FigureError(f"{p} holds no reconstructed BRDF (it is a {res.attrs.get('kind')} "
                          "result); render a scan's result")
    name = label or f"job {res.attrs.get('job_id')}: {res.attrs.get('specimen')}"
    rows: list[tuple[str, Any]] = []
    truth = true_material(res) if with_truth else None
    if truth is not None:
        rows.append((f"truth: {getattr(truth, 'name', 'simulated')}", truth))
    rows.append((f"{name} (reconstruction)", res.table))
    return rows


def render_inputs(paths: Sequence[str | os.PathLike[str]], size: int = render.DEFAULT_SIZE,
                  labels: Sequence[str | None] | None = None, title: str | None = None) -> bytes:
    """PNG of one or more results/tables. One input shows truth (if known) and reconstruction;
    several are compared row by row (each with its truth only when there is one input)."""
    if not paths:
        raise FigureError("nothing to render: give at least one result or table file")
    labels = list(labels or [None] * len(paths))
    rows: list[tuple[str, Any]] = []
    for p, lab in zip(paths, labels, strict=True):
        rows.extend(load_input(p, lab, with_truth=len(paths) == 1))
    if title is None:
        title = ("comparison: " if len(paths) > 1 else "") + ", ".join(r[0] for r in rows
                                                                      if "truth" not in r[0])
    return render.figure_png(rows, size=size, title=title)


# --------------------------------------------------------------------------- the error number
def headline_error(metrics: dict[str, Any]) -> dict[str, Any] | None:
    """The one error number to show for a result, with what it means in plain words.

    ``predicted_log_rmse`` when the result has it, else ``predicted_error`` (docs/science.md
    4.1); None when neither is there (calibration jobs, or no pair could be left out).

    Returns
    -------
    dict with ``key`` (metric name), ``value``, ``text`` (value as shown) and ``meaning``.
    """
    v = metrics.get("predicted_log_rmse")
    if isinstance(v, int | float):
        return {
            "key": "predicted_log_rmse", "value": float(v), "text": f"{v:.3f}",
            "meaning": "predicted log RMSE of the whole BRDF against the true material "
                       "(cosine-weighted, Löw et al. 2012): 0 is a perfect match, lower is "
                       "better; about 0.025 is typical of a good scan of a library-like "
                       "material (10 pairs x 8 angles). Materials unlike the training "
                       "library can be worse than predicted.",
        }
    v = metrics.get("predicted_error")
    if isinstance(v, int | float):
        return {
            "key": "predicted_error", "value": float(v), "text": f"{100 * v:.1f} %",
            "meaning": "predicted mean relative error of the whole reconstructed BRDF, from "
                       "leaving each pair out in turn: on average the reconstruction is "
                       "expected to be off by about this much. For half of the tested scans "
                       "the true error was within a factor 2.5 of it; materials unlike the "
                       "training library can be much worse.",
        }
    return None
