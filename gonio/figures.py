"""Renderings of result files: the reconstruction, the true material when it is known, and
comparisons of several results (``gonio render``, ``GET /api/v1/jobs/{id}/render.png``).

The pictures themselves come from :mod:`gonio.brdf.pictures.render`; this module knows where the
BRDFs are in a result file. A result measured on the simulated rig carries the simulated material
in its provenance (``true_material``, written by :func:`describe_material`), so its rendering
shows the truth beside the reconstruction, as V&F's Fig. 9 shows reference and reconstruction.
"""

from __future__ import annotations

import json
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from gonio.arc_wording import arc_sentence
from gonio.brdf.mirrorgap import gap_clause
from gonio.brdf.models import analytic as bm
from gonio.brdf.pictures import render
from gonio.brdf.tables.npzfile import ZIP_MAGIC, starts_with
from gonio.brdf.tables.table import BRDFTable
from gonio.results import ResultFile, read_result

TRUE_MATERIAL_KEY = "true_material"
"""Provenance attribute of a result file: JSON of :func:`describe_material` (simulated rigs)."""


class FigureError(ValueError):
    """An input cannot be rendered; the message says which and why."""


def describe_material(brdf: Any) -> dict[str, Any] | None:
    """JSON-ready recipe of a simulated specimen, or None if it cannot be written down.

    Analytic models are stored whole (:func:`gonio.brdf.models.analytic.to_dict`); a table is stored
    by the file it came from, when its provenance names one.
    """
    if isinstance(brdf, BRDFTable):
        src = brdf.provenance.get("file") or brdf.provenance.get("path")
        return {"name": brdf.name, "table_file": str(src)} if src else None
    bands = getattr(brdf, "bands", None)
    if bands is not None and hasattr(brdf, "spectral_eval"):  # gonio.sim.spectral
        return {"name": str(brdf.name), "spectral": str(brdf.name), "bands": bands.as_dict()}
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
        if "spectral" in desc:
            from gonio.brdf.colour.spectral import SpectralBands
            from gonio.sim.spectral import spectral_specimen

            return spectral_specimen(desc["spectral"], SpectralBands.from_dict(desc["bands"]))
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


def load_input(path: str | os.PathLike[str] | ResultFile, label: str | None = None,
               with_truth: bool = True) -> list[tuple[str, Any]]:
    """Figure rows for one input: a result file (``.h5``), a BRDF table (``.npz``), or a
    result file already read (the service's cached one: it is not read again).

    A result gives its reconstruction and, with ``with_truth``, the true material before it
    when known. Raises :class:`FigureError` for a file without a BRDF.
    """
    if isinstance(path, ResultFile):
        res, where = path, f"job {path.attrs.get('job_id')}'s result"
    else:
        p = Path(path)
        # A table saved under another name is a table too.
        if p.suffix.lower() == ".npz" or starts_with(p, ZIP_MAGIC):
            table = BRDFTable.load(p)
            return [(label or f"{p.name}: {table.name}", table)]
        res, where = read_result(p), str(p)
    if res.table is None:
        raise FigureError(f"{where} holds no reconstructed BRDF (it is a "
                          f"{res.attrs.get('kind')} result); render a scan's result")
    name = label or f"job {res.attrs.get('job_id')}: {res.attrs.get('specimen')}"
    rows: list[tuple[str, Any]] = []
    truth = true_material(res) if with_truth else None
    # A result with colour (spectral bands, a chart calibration) is shown in linear sRGB
    # computed from XYZ (docs/colour.md), not as its first three channels.
    from gonio.result_colour import linear_srgb, srgb_view

    srgb = linear_srgb(res)
    if truth is not None:
        rows.append((f"truth: {getattr(truth, 'name', 'simulated')}",
                     truth if srgb is None else srgb_view(res, truth)))
    rows.append((f"{name} (reconstruction)", res.table if srgb is None else srgb[0]))
    return rows


def render_inputs(paths: Sequence[str | os.PathLike[str] | ResultFile],
                  size: int = render.DEFAULT_SIZE,
                  labels: Sequence[str | None] | None = None, title: str | None = None) -> bytes:
    """PNG of one or more results/tables (paths, or result files already read,
    :func:`load_input`). One input shows truth (if known) and reconstruction; several are
    compared row by row (each with its truth only when there is one input)."""
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
def local_prior_text(metrics: dict[str, Any]) -> str | None:
    """The sentence for a joint fit that leaned on a folded-in table's shape (the metrics or
    settings' ``local_prior`` and ``local_prior_gain``; docs/science.md 7.2.3), or ``None``;
    the result's ``local_prior_own`` when that table is the specimen's own earlier result."""
    name = metrics.get("local_prior")
    if not name:
        return None
    own = metrics.get("local_prior_own")
    if own:
        return str(own)  # the specimen's own earlier result (gonio.finishing.own_result_prior)
    gain = metrics.get("local_prior_gain")
    how = f" by {gain:.1f} in log likelihood" if isinstance(gain, int | float) else ""
    return (f"prior: leaned on {name} where no pair looks (a measured or imported material of "
            f"the basis; its shape explains the readings better{how})")


def headline_error(metrics: dict[str, Any]) -> dict[str, Any] | None:
    """The one error number to show for a result, with what it means in plain words.

    ``predicted_log_rmse`` when the result has it, else ``predicted_error`` (docs/science.md
    4.1); None when neither is there (calibration jobs, or no pair could be left out).

    A result outside physical bounds, calibrated at another exposure than its scan's, or more
    than x2 from the expected error of the design
    its rig came from (``design_gap``, :mod:`gonio.designgap`), says so in ``text`` and starts
    ``meaning`` with the warning.

    Returns
    -------
    dict with ``key`` (metric name), ``value``, ``text`` (value as shown) and ``meaning``
    (and ``physical_bounds`` / ``calibration_warning`` / ``design_gap`` / ``arc_asymmetric``
    / ``basis_misfit`` / ``highlight_not_read`` when they apply; ``arc``,
    the sentence on the arc an auto-arc scan chose; ``uncovered_share`` and ``coverage``, the
    self-estimate's coverage witness and its sentence, when the result has it).
    """
    out = _headline(metrics)
    bounds = metrics.get("physical_bounds")
    if out is not None and isinstance(bounds, str):
        # Out of physical bounds, the estimate is beside the point: the headline says so first.
        out["text"] += " (OUTSIDE PHYSICAL BOUNDS)"
        out["meaning"] = f"Warning: {bounds}. {out['meaning']}"
        out["physical_bounds"] = bounds
    off = metrics.get("calibration_warning")
    if out is not None and isinstance(off, str):
        # The calibration was measured at another exposure: every value is off by the ratio.
        out["text"] += " (CALIBRATED AT ANOTHER EXPOSURE)"
        out["meaning"] = f"Warning: {off}. {out['meaning']}"
        out["calibration_warning"] = off
    gap = metrics.get("design_gap")
    if out is not None and isinstance(gap, str):
        # More than x2 from what the rig's design expected: the headline says so, and why.
        expected = metrics.get("design_expected_log_rmse")
        out["text"] += (f" (design expected {expected:.3g})"
                        if isinstance(expected, int | float) else " (far from its design)")
        out["meaning"] = f"Warning: {gap}. {out['meaning']}"
        out["design_gap"] = gap
    asym = metrics.get("arc_asymmetric")
    if out is not None and isinstance(asym, str):
        # A forced half turn on a specimen that is not twofold symmetric: the other half
        # turn is an assumption the readings contradict.
        out["text"] += " (NOT TWOFOLD SYMMETRIC)"
        out["meaning"] = f"Warning: {asym}. {out['meaning']}"
        out["arc_asymmetric"] = asym
    elif out is not None and isinstance(metrics.get("arc_symmetric"), bool) and \
            isinstance(metrics.get("arc_test_p_value"), int | float):
        out["arc"] = arc_sentence(metrics)
        out["meaning"] = f"{out['meaning']} {out['arc']}"
    uncovered = metrics.get("uncovered_share")
    if out is not None and out["key"] == "predicted_log_rmse" and \
            isinstance(uncovered, int | float):
        # The coverage witness the estimate was mapped with (docs/science.md 7.1.1): how much
        # of the table the layout leaves to the prior, the part no reading can show.
        out["uncovered_share"] = float(uncovered)
        out["coverage"] = (f"The readings leave {100 * uncovered:.1f} % of the prior's "
                           "weighted variance uncovered (uncovered_share: the part of the "
                           "table no pair looks at, part of the estimate).")
        out["meaning"] = f"{out['meaning']} {out['coverage']}"
    upper = metrics.get("predicted_log_rmse_upper")
    if out is not None and out["key"] == "predicted_log_rmse" and isinstance(upper, int | float):
        # The upper end of the estimate's interval: what to plan with when the result must not
        # be worse than it is told (docs/science.md 7.1.1).
        out["upper"] = float(upper)
        out["interval"] = (f"Upper end of its interval: {upper:.3f} (predicted_log_rmse_upper; "
                           "its factors put the true error of held-out materials below it on "
                           "98 % of the calibration scans; the test and fresh scans were seen "
                           "while the interval's form was chosen).")
        out["meaning"] = f"{out['meaning']} {out['interval']}"
    lean = metrics.get("local_prior")
    if out is not None and out["key"] == "predicted_log_rmse" and isinstance(lean, str):
        # The fit leaned on a folded-in material's shape where no pair looks (docs/science.md
        # 7.2.3): what the CLI prints as its "prior:" line, said where the page shows the error.
        out["local_prior"] = lean
        out["prior"] = (f"Where no pair looks, the fit leaned on the shape of '{lean}', the "
                        "measured or imported material the readings favour (local_prior).")
        out["meaning"] = f"{out['meaning']} {out['prior']}"
    misfit = metrics.get("basis_misfit")
    if out is not None and isinstance(misfit, str):
        # The readings carry structure the basis cannot hold: the estimate is a floor at best,
        # and the headline says so before anyone trusts it.
        out["text"] += " (BASIS MISFIT)"
        out["meaning"] = f"Warning: {misfit}. {out['meaning']}"
        out["basis_misfit"] = misfit
    unread = metrics.get("highlight_not_read")
    if out is not None and isinstance(unread, str):
        # No reading comes near the table's peak: the highlight is the prior's extrapolation
        # (gonio.brdf.highlightread, docs/science.md 7.1.1); the number covers the rest.
        out["text"] += " (HIGHLIGHT NOT READ)"
        out["meaning"] = f"Warning: {unread}. {out['meaning']}"
        out["highlight_not_read"] = unread
    mirror = metrics.get("mirror_gap")
    if out is not None and out["key"] == "predicted_log_rmse" and isinstance(mirror, str):
        # A fact of the layout, not of this scan (gonio.brdf.mirrorgap): said beside the
        # estimate it limits, without marking the headline, since most specimens have no
        # highlight that narrow. With the highlight-not-read warning above it, which already
        # says to read a pair near the mirror direction, the gap alone.
        tilt = metrics.get("mirror_gap_deg")
        said = (gap_clause(float(tilt)) if isinstance(unread, str)
                and isinstance(tilt, int | float) else mirror)
        out["meaning"] = f"{out['meaning']} Note: {said}."
        out["mirror_gap"] = mirror
    return out


def _headline(metrics: dict[str, Any]) -> dict[str, Any] | None:
    v = metrics.get("predicted_log_rmse")
    if isinstance(v, int | float):
        return {
            "key": "predicted_log_rmse", "value": float(v), "text": f"{v:.3f}",
            "meaning": "predicted log RMSE of the whole BRDF against the true material "
                       "(cosine-weighted, Löw et al. 2012): 0 is a perfect match, lower is "
                       "better. It adds what the readings leave undetermined, how far the "
                       "material sits from the training library, how far the table's "
                       "highlight stands above every reading and how far readings stand "
                       "above what the other pairs predict; on materials held out of "
                       "the library it was within a factor of 2 of the truth on about 2 "
                       "scans in 3 (187 of 290 test and fresh scans) and more than 2 times "
                       "too low on about 1 in 100 (3 of 290, all read with the MA98 preset); "
                       "on two later sets of 60 holding clear coats and mirror-smooth "
                       "plastics over bright bodies, 3 and 16 (a mirror peak only one pair, "
                       "or no reading, sees; 13 of them read with presets) "
                       "(docs/science.md 7.1.1).",
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


# --------------------------------------------------------------------------- plot data
def _units(res: ResultFile) -> str:
    return "1/sr" if res.samples.calibration.get("pairs") else "sensor units (uncalibrated)"


def _mean_or_none(v: Any) -> list[float | None]:
    """Mean over channels of (N, C) values as JSON numbers (None where not finite)."""
    import numpy as np

    m = np.asarray(v, dtype=float).mean(axis=-1)
    return [float(x) if np.isfinite(x) else None for x in m]


def fit_curves(res: ResultFile, step_deg: float = 2.0) -> dict[str, Any]:
    """Each pair's calibrated samples against stage angle and the reconstruction through them.

    The curve evaluates the reconstructed table at the pair's fixed lab directions turned
    into the specimen frame at each stage angle
    (:func:`gonio.brdf.tables.geometry.lab_to_specimen`).
    Values are the mean over channels.

    Returns
    -------
    dict: ``units``, ``calibrated`` (False: sensor units), ``curve_deg`` (stage angles of
    the curves), ``pairs``: list of
    ``{label, stage_deg, measured, curve}``.
    """
    import numpy as np

    from gonio.brdf.tables import geometry as geo

    if res.table is None:
        raise FigureError("this result has no reconstructed BRDF (a calibration job)")
    s = res.samples
    curve_deg = np.arange(0.0, 360.0 + 1e-9, step_deg)
    alphas = np.deg2rad(curve_deg)
    n_pairs, n_a = len(s.pairs), alphas.size
    # Every pair's curve in one lookup, so the cubic's nodes are computed once, and only at
    # the cells these few hundred points read (render.TableLookup, "auto").
    turns = np.tile(alphas, n_pairs)
    wi = geo.lab_to_specimen(np.repeat(np.asarray(s.light_dirs, dtype=float), n_a, axis=0), turns)
    wo = geo.lab_to_specimen(np.repeat(np.asarray(s.sensor_dirs, dtype=float), n_a, axis=0), turns)
    curves = render.TableLookup(res.table).eval(wi, wo).reshape(n_pairs, n_a, -1)
    pairs = []
    order = np.argsort(np.mod(s.stage_angles_deg, 360.0))
    stage = np.mod(s.stage_angles_deg, 360.0)[order]
    for q, (light, sensor) in enumerate(s.pairs):
        pairs.append({
            "label": f"{light}/{sensor}",
            "stage_deg": [float(a) for a in stage],
            "measured": _mean_or_none(np.asarray(s.values[q])[order]),
            "curve": _mean_or_none(curves[q]),
        })
    return {"units": _units(res), "calibrated": bool(s.calibration.get("pairs")),
            "channels": _channels_text(s.channels),
            "curve_deg": [float(a) for a in curve_deg], "pairs": pairs}


def _channels_text(channels: Sequence[str]) -> str:
    """What the fit's curves average, for the page's y axis: "mean of R, G, B"; many channels
    (a 31-band spectrometer's) by count and range, not 31 names past the axis."""
    if len(channels) <= 4:
        return "mean of " + ", ".join(channels)
    return f"mean of {len(channels)} channels, {channels[0]} to {channels[-1]}"


def polar_curves(res: ResultFile, theta_i_deg: float, phi_i_deg: float) -> dict[str, Any]:
    """In-plane and cross-plane BRDF at one incidence, for the result and its truth if known.

    In-plane: views in the plane of incidence, ``theta_o`` from -89 to 89 degrees, positive
    on the specular side (azimuth ``phi_i + 180``). Cross-plane: views in the plane through
    the mirror direction perpendicular to the plane of incidence, at ``-89 .. 89`` degrees
    from the mirror direction. Angles are in the specimen frame (``phi_i`` from the holder
    mark).
    """
    import numpy as np

    if res.table is None:
        raise FigureError("this result has no reconstructed BRDF (a calibration job)")
    ti, pi_ = np.deg2rad(theta_i_deg), np.deg2rad(phi_i_deg)
    wi = np.array([np.sin(ti) * np.cos(pi_), np.sin(ti) * np.sin(pi_), np.cos(ti)])
    ang = np.arange(-89.0, 89.0 + 1e-9, 1.0)
    a = np.deg2rad(ang)
    # In-plane: the view turns in the incidence plane; +theta towards the specular side.
    fwd = np.array([-np.cos(pi_), -np.sin(pi_), 0.0])  # horizontal, away from the light
    in_plane = np.sin(a)[:, None] * fwd + np.cos(a)[:, None] * np.array([0.0, 0.0, 1.0])
    mirror = np.array([-wi[0], -wi[1], wi[2]])
    perp = np.array([-np.sin(pi_), np.cos(pi_), 0.0])
    cross = np.cos(a)[:, None] * mirror + np.sin(a)[:, None] * perp
    wis = np.broadcast_to(wi, in_plane.shape)

    def curves(brdf: Any) -> dict[str, dict[str, list[float | None]]]:
        f = render.evaluator(brdf)
        chans = list(getattr(brdf, "channels", None) or res.table.channels)  # type: ignore[union-attr]
        out = {}
        for name, wo in (("in_plane", in_plane), ("cross_plane", cross)):
            v = np.asarray(f(wis, wo))
            out[name] = {ch: [float(x) if np.isfinite(x) else None for x in v[:, c]]
                         for c, ch in enumerate(chans[: v.shape[1]])}
        return out

    truth = true_material(res)
    return {
        "theta_i_deg": float(theta_i_deg), "phi_i_deg": float(phi_i_deg),
        "angle_deg": [float(x) for x in ang], "units": _units(res),
        "reconstruction": curves(res.table),
        "truth": curves(truth) if truth is not None else None,
        "truth_name": getattr(truth, "name", None) if truth is not None else None,
    }
