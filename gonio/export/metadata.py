"""What an exported file says about itself: one JSON-ready record, the same in every format.

Every export carries :func:`export_provenance`: in the glTF ``asset.extras`` and the material's
``extras``, in the MaterialX material's ``doc`` string and as ``gonio_*`` attributes, in the
``.npz`` formats' ``provenance`` entry, and in a ``.json`` sidecar beside a MERL file (whose
layout has no room). Keys (docs/export.md lists them with examples):

``gonio_provenance``
    Version of this record (:data:`VERSION`).
``specimen``, ``specimen_named``
    The name given at the scan; ``"unnamed"`` and ``false`` when none was given (older gonio
    versions wrote the placeholder ``specimen``, read as unnamed too).
``source``
    ``"simulated"`` (a simulated rig; ``simulated_material`` then holds the material's recipe)
    or ``"measured"``.
``reconstruction_error``
    The headline self-estimate ``predicted_log_rmse`` with its meaning and unit, the upper
    end of its interval ``predicted_log_rmse_upper`` when the result stores it, and the
    layout's ``mirror_gap_deg`` (with ``mirror_gap``, what it hides, above 1 degree;
    :mod:`gonio.brdf.mirrorgap`) when the result stores it.
``rig``, ``plan``, ``calibration``
    The rig's name and the pairs measured, the plan (design, rotations, arc), the calibration's
    reference, albedo and date.
``colour_space``
    What the R, G, B numbers are (:data:`COLOUR_STATEMENT` unless the result states another).
``orientation``
    How the anisotropy direction is referred to the specimen and to a mesh (:data:`ORIENTATION`).
``symmetry``
    How far the result is from twofold symmetry (``twofold_asymmetry``,
    :func:`gonio.brdf.tables.twofold.twofold_asymmetry`) and which formats can hold an
    asymmetric result: the principled glTF and MaterialX models are twofold symmetric (a GGX
    lobe reads the same turned by half a turn), MERL is isotropic, the table and factored
    formats keep the asymmetry.
``fits``
    Each model's fit error against the reconstruction: table metrics and the rendered
    difference (:mod:`gonio.export.judge`).
``reconstruction_warnings``
    The warnings about the reconstruction itself (a calibration at another exposure, the
    arc, outside physical bounds, a design gap, a basis misfit): the ``table`` export's.
``warnings``
    Plain sentences: large rendered differences, an averaged-away anisotropy, a calibration
    measured at another exposure than the scan, a half-turn
    scan's arc, a reconstruction outside physical bounds (docs/science.md 7.5), a
    self-estimate more than x2 from its design's expected error (7.1), ...
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from typing import Any

from gonio import __version__

VERSION = 1
#: The specimen name of a scan started without one.
UNNAMED = "unnamed"
#: The placeholder older gonio versions stored when no name was given.
_OLD_PLACEHOLDER = "specimen"

COLOUR_STATEMENT = (
    "uncalibrated sensor RGB: the rig's sensors' R, G, B channels, each scaled to 1/sr by a "
    "white reference, written unchanged as linear sRGB factors; no colour calibration maps "
    "them to sRGB primaries or a white point"
)
"""What the colour channels of an export are today. A result whose provenance has a
``colour_space`` entry (set by colour calibration) states that instead."""

UNCALIBRATED_COLOUR_STATEMENT = (
    "uncalibrated sensor units: the rig's sensors' R, G, B channels as read (dark "
    "subtracted), with no white reference: not 1/sr, and no colour space"
)
"""What the channels of a scan measured with no white-reference calibration are: the
:data:`COLOUR_STATEMENT`'s "scaled to 1/sr by a white reference" would be untrue."""

UNCALIBRATED_WARNING = (
    "uncalibrated: the scan had no white-reference calibration, so this material's values are "
    "sensor units, not 1/sr; each light/sensor pair is off by its own factor and a renderer "
    "shows it too bright or too dark. Calibrate with the white reference on the stage "
    "(gonio scan --white-reference 0.99, or the page's calibration) and scan again"
)
"""The warning every export of such a scan carries, first among its reconstruction
warnings (the table's included: a table in sensor units trains a basis wrongly)."""

ORIENTATION: dict[str, str] = {
    "specimen_frame": "x = the reference mark on the specimen holder (+u of the specimen), "
                      "z = the surface normal, y = z cross x (right-handed)",
    "direction": "the anisotropy direction is the azimuth of the rougher GGX axis (the one the "
                 "highlight stretches along), counter-clockwise from x seen from above, in "
                 "[0, 180) degrees",
    "mesh": "put the material on a mesh whose tangent (glTF TANGENT.xyz, MaterialX Tworld) "
            "runs along the specimen's x, with bitangent = normal cross tangent (glTF "
            "TANGENT.w = +1); a mesh without tangents leaves the direction to the viewer's "
            "choice of tangent (glTF: derived from the TEXCOORD_0 u direction)",
}

LOG_RMSE_MEANING = (
    "predicted_log_rmse: the reconstruction's own estimate of its error against the true "
    "material, the cosine-weighted RMS difference of log(1 + f cos theta_i) over the "
    "hemispheres (Löw et al. 2012; f in 1/sr), dimensionless; 0 is a perfect match, 0.05 is "
    "about a 5 % error where a rendering is bright. Calibrated on materials held out of the "
    "basis; within a factor of 2 of the truth on about 2 scans in 3 (187 of 290 test and fresh "
    "scans), more than 2 times too low on about 1 in 100 (3 of 290, the MA98 preset); on two "
    "later sets of 60 holding clear coats and mirror-smooth plastics over bright bodies, 3 and "
    "16 (a mirror peak only one pair, or no reading, sees; 13 of them read with presets); the "
    "interval's upper end (predicted_log_rmse_upper) is set so the true error was below it on "
    "98 % of the calibration scans; the test and fresh scans were seen while its form was "
    "chosen (docs/science.md 7.1.1)"
)

#: ``twofold_asymmetry`` above which an export warns that the principled models lose the
#: difference between the specimen and itself turned by half a turn (the same scale as the MERL
#: sidecar's ``anisotropy_lost`` warning, :data:`gonio.export.merl.ANISOTROPY_WARN`).
TWOFOLD_WARN = 0.01

SYMMETRY_STATEMENT = (
    "the principled models (glTF KHR_materials_anisotropy, MaterialX standard_surface) are "
    "twofold symmetric: a GGX lobe reads the same when the material is turned by half a turn, "
    "so they hold only the half-turn average of the result; MERL is isotropic; the table and "
    "factored formats keep a result without that symmetry as measured"
)
TWOFOLD_MEANING = (
    "cosine-weighted log RMSE between the result and its half-turn average "
    "(f(ph) + f(ph + 180 deg)) / 2; 0 for a twofold-symmetric result"
)


def symmetry_record(twofold_asymmetry: float) -> tuple[dict[str, Any], str | None]:
    """The ``symmetry`` record of an export and its warning (None below :data:`TWOFOLD_WARN`).

    Parameters
    ----------
    twofold_asymmetry : float
        :func:`gonio.brdf.tables.twofold.twofold_asymmetry` of the result's table
        (dimensionless log RMSE).
    """
    record = {"twofold_asymmetry": float(twofold_asymmetry),
              "twofold_asymmetry_meaning": TWOFOLD_MEANING, "formats": SYMMETRY_STATEMENT}
    if not twofold_asymmetry > TWOFOLD_WARN:
        return record, None
    return record, (
        f"the result is not twofold symmetric (log RMSE {twofold_asymmetry:.3f} to its "
        "half-turn average): the glTF and MaterialX principled models are symmetric and show "
        "only that average; use the 'table' or 'factored' export to keep the difference"
    )


def _json(value: Any) -> Any:
    """A provenance attribute that may hold JSON text, decoded (text that is not JSON stays)."""
    if isinstance(value, str):
        try:
            return json.loads(value)
        except ValueError:
            return value
    return value


def specimen_name(name: Any) -> tuple[str, bool]:
    """``(name, named)``: the given name, or :data:`UNNAMED` and False when there is none."""
    text = str(name or "").strip()
    if not text or text in (_OLD_PLACEHOLDER, UNNAMED):
        return UNNAMED, False
    return text, True


def _rig_summary(rig: Any) -> dict[str, Any] | None:
    """The rig's lights, sensors, pair count and stage range (the whole rig snapshot stays in
    the result file, :class:`gonio.rigdescription.RigDescription`)."""
    rig = _json(rig)
    if not isinstance(rig, Mapping):
        return None
    out: dict[str, Any] = {}
    for part in ("lights", "sensors"):
        items = rig.get(part)
        if isinstance(items, list):
            out[part] = [i.get("name") for i in items if isinstance(i, Mapping)]
    if isinstance(rig.get("pairs"), list):
        out["n_pairs"] = len(rig["pairs"])
    if "stage_min_deg" in rig and "stage_max_deg" in rig:
        out["stage_deg"] = [rig["stage_min_deg"], rig["stage_max_deg"]]
    return out


def _calibration_summary(cal: Any, warning: Any) -> dict[str, Any]:
    cal = _json(cal)
    out: dict[str, Any] = {"calibrated": False, "reference": None, "date": None}
    if isinstance(cal, Mapping):
        out.update(
            calibrated=bool(cal.get("pairs")), reference=cal.get("source"),
            reference_albedo=cal.get("reference_albedo"), exposure_s=cal.get("exposure_s"),
            date=cal.get("created"),
        )
    if warning:
        out["warning"] = warning
    return out


def export_provenance(attrs: Mapping[str, Any], metrics: Mapping[str, Any],
                      provenance: Mapping[str, Any], fits: Mapping[str, Any],
                      warnings: list[str] | None = None,
                      twofold_asymmetry: float | None = None) -> dict[str, Any]:
    """The record every export carries (module docstring for its keys).

    Parameters
    ----------
    attrs, metrics, provenance : mappings
        The result file's root attributes, ``/metrics`` and ``/provenance``
        (:class:`gonio.results.ResultFile`).
    fits : mapping
        ``{"principled": {...}, "factored": {...}}``: each model's fit errors.
    warnings : list of str, optional
    twofold_asymmetry : float, optional
        The result table's distance from twofold symmetry (:func:`symmetry_record`); the
        ``symmetry`` key is left out when not given.
    """
    name, named = specimen_name(attrs.get("specimen"))
    truth = _json(provenance.get("true_material"))
    v = metrics.get("predicted_log_rmse")
    rec_error: dict[str, Any] = {
        "predicted_log_rmse": float(v) if isinstance(v, int | float) else None,
        "meaning": LOG_RMSE_MEANING,
    }
    upper = metrics.get("predicted_log_rmse_upper")
    if isinstance(upper, int | float):
        # The upper end of the estimate's interval (docs/science.md 7.1.1); results made
        # before it was stored have none.
        rec_error["predicted_log_rmse_upper"] = float(upper)
    gap = metrics.get("mirror_gap_deg")
    if isinstance(gap, int | float):
        # What the estimate cannot see: a highlight narrower than the layout's distance from
        # the mirror direction (docs/science.md 7.1.1.2); results made before have none.
        rec_error["mirror_gap_deg"] = float(gap)
        if isinstance(metrics.get("mirror_gap"), str):
            rec_error["mirror_gap"] = str(metrics["mirror_gap"])
    if not isinstance(v, int | float):
        rec_error["note"] = "this result has no predicted_log_rmse (an older result, or no " \
                            "pair could be left out)"
    plan = _json(provenance.get("plan"))
    cal = _json(provenance.get("calibration"))
    # Only a result that records its calibration and that it had none: older results without
    # the record are not called uncalibrated.
    uncalibrated = isinstance(cal, Mapping) and not cal.get("pairs")
    colour_space = provenance.get("colour_space") or (
        UNCALIBRATED_COLOUR_STATEMENT if uncalibrated else COLOUR_STATEMENT)
    out: dict[str, Any] = {
        "gonio_provenance": VERSION,
        "generator": f"gonio {attrs.get('gonio_version') or __version__}",
        "exported_by": f"gonio {__version__}",
        "job_id": attrs.get("job_id"),
        "specimen": name, "specimen_named": named,
        "source": "simulated" if truth else "measured",
        "measured_at": attrs.get("created"),
        "reconstruction_error": rec_error,
        "rig": _rig_summary(provenance.get("rig")),
        "plan": plan if isinstance(plan, Mapping) else None,
        "calibration": _calibration_summary(provenance.get("calibration"),
                                            provenance.get("calibration_warning")),
        "colour_space": str(colour_space),
        "orientation": dict(ORIENTATION),
        "fits": dict(fits),
        "warnings": list(warnings or []),
    }
    if twofold_asymmetry is not None:
        record, warning = symmetry_record(twofold_asymmetry)
        out["symmetry"] = record
        if warning is not None:
            out["warnings"].append(warning)
    if truth:
        out["simulated_material"] = truth
    # The reconstruction's own warnings (the calibration does not fit the scan, the arc, a
    # table outside physical bounds, ...): they hold for every format, the table's included.
    recon = [str(provenance[k]) for k in RECONSTRUCTION_WARNINGS if provenance.get(k)]
    if uncalibrated:
        recon.insert(0, UNCALIBRATED_WARNING)
    out["warnings"].extend(recon)
    out["reconstruction_warnings"] = recon
    return out


RECONSTRUCTION_WARNINGS = ("calibration_warning", "arc_warning", "physical_bounds", "design_gap",
                           "basis_misfit", "local_prior_own", "highlight_not_read")
"""The result provenance's warnings about the reconstruction itself, in the order an export
lists them (``reconstruction_warnings``; also at the end of ``warnings``)."""
