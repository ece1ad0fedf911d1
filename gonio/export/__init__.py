"""Materials out of the lab: a job's result file in formats renderers and other tools read.

========== ========== ===================================================================
format     suffix     what
========== ========== ===================================================================
factored   ``.npz``   the factored fit of paper 000 (:mod:`gonio.brdf.models.factored`)
mtlx       ``.mtlx``  MaterialX ``standard_surface`` and ``open_pbr_surface`` (:mod:`.mtlx`)
gltf       ``.gltf``  glTF 2.0 material with ``KHR_materials_anisotropy`` (:mod:`.gltf`)
glb        ``.glb``   the same glTF document in the binary GLB container (:func:`.gltf.write_glb`)
merl       ``.binary`` MERL layout, azimuthally averaged, with a ``.json`` sidecar (:mod:`.merl`)
table      ``.npz``   gonio's own BRDF table (:class:`gonio.brdf.tables.table.BRDFTable`)
========== ========== ===================================================================

The fits come from the result file (the daemon stores them when it reconstructs); a result
written before they existed, or before the principled fit was judged by rendering
(:mod:`.judge`), is fitted here, which takes some seconds. Every format carries the provenance
of :mod:`.metadata` (MERL in a sidecar); each export reports its fitted model's rendered
difference from the reconstruction and warns when it is large.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from gonio.brdf.models.factored import FactoredBRDF, fit_factored
from gonio.brdf.models.principled import Principled, fit_principled
from gonio.brdf.tables.table import BRDFTable

FORMATS: dict[str, str] = {
    "factored": ".npz", "mtlx": ".mtlx", "gltf": ".gltf", "glb": ".glb", "merl": ".binary",
    "table": ".npz",
}
MEDIA_TYPES: dict[str, str] = {
    "factored": "application/octet-stream", "mtlx": "application/xml",
    "gltf": "model/gltf+json", "glb": "model/gltf-binary", "merl": "application/octet-stream",
    "table": "application/octet-stream",
}
#: The formats that can carry the preview sphere (``with_mesh``; :func:`.gltf.preview_sphere`).
MESH_FORMATS: tuple[str, ...] = ("gltf", "glb")
#: Iterations of the factored fit when it runs at export or reconstruction time.
FIT_ITERATIONS = 10


class ExportError(ValueError):
    """An export cannot be made; the message says why and what to do."""


@dataclass(frozen=True)
class Fits:
    """A result's table and the two fits every export format starts from.

    ``srgb_table`` is the table in linear sRGB from XYZ when the result's channels have colour
    (spectral bands, or an RGB sensor with a chart calibration;
    :func:`gonio.result_colour.linear_srgb`), which the fits were made of and MERL is written
    from; None when they have none (uncalibrated sensor RGB, written as it is).
    """

    table: BRDFTable
    factored: FactoredBRDF
    principled: Principled
    srgb_table: BRDFTable | None = None


def fit_all(table: BRDFTable) -> Fits:
    """Factored and principled fits of a reconstructed table, judged by rendering (seconds of
    CPU): the principled fit is refined on renderings (:func:`.judge.fit_principled_rendered`)
    and each model's ``metrics["rendered"]`` is its rendered difference from ``table``."""
    from gonio.brdf.reconstruction.blas import one_blas_thread
    from gonio.export.judge import fit_principled_rendered

    # One BLAS thread: the fits' products and small SVDs gain nothing from more, and on a
    # shared 2-core machine OpenBLAS' spinning threads doubled the fits' CPU time
    # (docs/export.md, "What the fits cost"). The results are the same.
    with one_blas_thread():
        principled, _ = fit_principled_rendered(table, fit_principled(table))
        factored = _judged_factored(table, fit_factored(table, iterations=FIT_ITERATIONS))
    return Fits(table, factored, principled)


def _judged_factored(table: BRDFTable, factored: FactoredBRDF) -> FactoredBRDF:
    """``factored`` with its rendered difference from ``table`` in ``metrics["rendered"]``."""
    from gonio.export.judge import rendered_difference

    if "rendered" in factored.metrics or table.n_channels != 3:
        return factored
    diff = rendered_difference(table, factored)
    return replace(factored, metrics={**factored.metrics, "rendered": diff.as_dict()})


def check_format(fmt: str) -> str:
    """``fmt`` if it is a known format, else :class:`ExportError` listing them."""
    if fmt not in FORMATS:
        raise ExportError(f"unknown export format {fmt!r}; use one of {', '.join(FORMATS)}")
    return fmt


def result_fits(result_path: str | os.PathLike[str]) -> tuple[Fits, dict[str, Any]]:
    """The fits of a result file (stored ones, else fitted now), its table in linear sRGB
    when it has colour (:attr:`Fits.srgb_table`), and its provenance."""
    from gonio.result_colour import linear_srgb
    from gonio.results import ResultFileError, read_result

    try:
        res = read_result(result_path)
    except ResultFileError as exc:
        raise ExportError(str(exc)) from None
    if res.table is None:
        raise ExportError(
            f"{Path(result_path).name} is a {res.attrs.get('kind', '?')} job's result without a "
            "reconstructed BRDF; export a scan's result"
        )
    from gonio.brdf.reconstruction.blas import one_blas_thread
    from gonio.export.judge import fit_principled_rendered

    with one_blas_thread():  # as in fit_all
        factored = _judged_factored(
            res.table, res.factored or fit_factored(res.table, iterations=FIT_ITERATIONS))
        principled = res.principled
        if principled is None or principled.metrics.get("fit") != "rendered":
            # Missing, or fitted on the table alone by an older gonio (issue 26): fit again.
            principled, _ = fit_principled_rendered(res.table, fit_principled(res.table))
    srgb = linear_srgb(res)
    fits = Fits(res.table, factored, principled, None if srgb is None else srgb[0])
    return fits, provenance(res.attrs, fits, res.metrics, res.provenance)


def fit_summary(fits: Fits) -> dict[str, Any]:
    """Each model's fit errors against the reconstruction: table metrics and rendered."""
    keys = ("rel_mse", "mape", "psnr", "log_rmse", "rendered")
    return {"principled": {k: fits.principled.metrics.get(k) for k in keys},
            "factored": {k: fits.factored.metrics.get(k) for k in keys}}


def _rendered_value(metrics: Any) -> tuple[float, dict[str, Any]] | None:
    """A fit's stored rendered difference and its record, if it has one."""
    r = metrics.get("rendered")
    if not isinstance(r, dict) or not isinstance(r.get("value"), int | float):
        return None
    return float(r["value"]), r


def fit_warnings(fits: Fits) -> dict[str, list[str]]:
    """Each fitted model's warnings, by model (``"principled"``, ``"factored"``): a sentence
    for a model whose rendering differs much from the reconstruction's, and, for the
    principled model, one when the factored model renders much closer (a material one
    principled lobe cannot show, :data:`.judge.TWO_LOBE_RATIO`).

    They are kept apart because each export holds one model: a glTF file said "the factored
    fit renders visibly unlike the reconstruction", which is not about the file it is in
    (:func:`format_provenance`).
    """
    from gonio.export.judge import TWO_LOBE_RATIO, WARN_FLIP, WARN_RELATIVE

    out: dict[str, list[str]] = {"principled": [], "factored": []}
    for what, m in (("principled", fits.principled.metrics), ("factored", fits.factored.metrics)):
        got = _rendered_value(m)
        if got is None:
            continue
        value, r = got
        limit = WARN_FLIP if r.get("flip") is not None else WARN_RELATIVE
        if value > limit:
            out[what].append(
                f"the {what} fit renders visibly unlike the reconstruction ({r['metric']} "
                f"{value:.3f} > {limit:g}): this model does not represent the material "
                "well; use the 'table' export where a renderer can take a table")
    p, f = _rendered_value(fits.principled.metrics), _rendered_value(fits.factored.metrics)
    if p is not None and f is not None and p[1].get("metric") == f[1].get("metric"):
        limit = WARN_FLIP if p[1].get("flip") is not None else WARN_RELATIVE
        if p[0] > limit and p[0] > TWO_LOBE_RATIO * f[0]:
            out["principled"].append(
                f"one principled material cannot show this material: the factored model's "
                f"rendered difference from the reconstruction is {p[0] / max(f[0], 1e-12):.1f}"
                f"x smaller ({p[1]['metric']} {f[0]:.3f} against {p[0]:.3f}). Typically two "
                "lobes, such as a diffuse colour under a coloured highlight of another hue (a "
                "metallic paint) or two highlights, which principled parameters tie together; "
                "use the 'factored' (or 'table') export for this material")
    return out


def provenance(attrs: dict[str, Any], fits: Fits, metrics: dict[str, Any],
               result_provenance: dict[str, Any] | None = None) -> dict[str, Any]:
    """What an exported file says about itself (:func:`.metadata.export_provenance`).

    Its ``warnings`` are every model's and the reconstruction's; ``model_warnings`` keeps each
    fitted model's apart, for :func:`format_provenance`, which gives each format its own.
    """
    from gonio.brdf.tables.twofold import twofold_asymmetry
    from gonio.export.metadata import export_provenance

    by_model = fit_warnings(fits)
    prov = export_provenance(attrs, metrics, result_provenance or {}, fit_summary(fits),
                             by_model["principled"] + by_model["factored"],
                             twofold_asymmetry(fits.table))
    prov[MODEL_WARNINGS] = by_model
    return prov


MODEL_WARNINGS = "model_warnings"
"""The provenance key (:func:`provenance`) that holds each fitted model's warnings until
:func:`format_provenance` picks a format's; no file carries it."""


def format_provenance(fmt: str, prov: dict[str, Any]) -> dict[str, Any]:
    """The record one format's file carries: ``prov`` with the ``warnings`` that are about it.

    * ``table``, the reconstruction itself, and ``merl``, the table averaged over azimuth (no
      fit): the reconstruction's own (``reconstruction_warnings``: calibration, arc, physical
      bounds, design gap, misfit); MERL's sidecar adds the anisotropy the average lost;
    * ``gltf``, ``glb`` and ``mtlx``, the principled fit: its warnings, that the principled model is
      twofold symmetric when the result is not, and the reconstruction's own;
    * ``factored``: the factored fit's warnings and the reconstruction's own.

    A record without ``model_warnings`` (written by an older gonio) keeps its ``warnings`` for
    the fitted formats.
    """
    from gonio.export.metadata import symmetry_record

    recon = [str(w) for w in prov.get("reconstruction_warnings") or []]
    out = {k: v for k, v in prov.items() if k != MODEL_WARNINGS}
    by_model = prov.get(MODEL_WARNINGS)
    if fmt in ("table", "merl"):
        out["warnings"] = recon
    elif isinstance(by_model, dict):
        model = "factored" if fmt == "factored" else "principled"
        own = [str(w) for w in by_model.get(model) or []]
        sym = prov.get("symmetry")
        if model == "principled" and isinstance(sym, dict) and isinstance(
                sym.get("twofold_asymmetry"), int | float):
            # The principled models are twofold symmetric; the factored one and the table
            # keep what differs at ph + 180 deg.
            _, said = symmetry_record(float(sym["twofold_asymmetry"]))
            own += [said] if said else []
        out["warnings"] = own + recon
    return out


def write_export(fits: Fits, fmt: str, out: str | os.PathLike[str],
                 prov: dict[str, Any], *, with_mesh: bool = False) -> Path:
    """Write one format from fits already in hand; returns the path.

    ``with_mesh`` adds the glTF's preview sphere (:func:`.gltf.preview_sphere`; ``gltf`` and
    ``glb``).
    """
    from gonio.export.gltf import GltfError
    from gonio.export.merl import MerlError
    from gonio.export.mtlx import MtlxError

    check_format(fmt)
    try:
        return _write(fits, fmt, out, prov, with_mesh)
    except (MerlError, MtlxError, GltfError) as exc:
        # MerlError, MtlxError, GltfError (e.g. a table that is not R, G, B): the caller (the
        # daemon turns ExportError into a 404 with the reason) gets one error type to handle.
        raise ExportError(
            f"cannot write {fmt}: {exc}; the 'table' and 'factored' formats keep any channels"
        ) from None


def _write(fits: Fits, fmt: str, out: str | os.PathLike[str], prov: dict[str, Any],
           with_mesh: bool) -> Path:
    prov = format_provenance(fmt, prov)
    name = str(prov.get("specimen") or fits.table.name)
    if prov.get("job_id") is not None:
        name = f"{name}_job{prov['job_id']}"  # unnamed scans stay apart in a scene
    if fmt == "table":
        own = dict(prov)
        if fits.srgb_table is not None and prov.get("colour_space"):
            # Its channels are the sensor's own (bands, or raw RGB), not the linear sRGB the
            # other formats hold: say what they are and how colour is made of them.
            own["colour_space"] = (
                f"the reconstruction's own channels ({', '.join(fits.table.channels)}), as "
                f"measured, not sRGB; the other exports hold {prov['colour_space']}")
        table = BRDFTable.trusted(
            fits.table.values, fits.table.channels, fits.table.name, fits.table.wavelengths_nm,
            {**fits.table.provenance, **own},
        )
        return table.save(out)
    if fmt == "factored":
        return fits.factored.save(out, prov)
    if fmt == "mtlx":
        from gonio.export.mtlx import write_mtlx

        # The open_pbr_surface beside the standard_surface carries the same fit, with a white
        # F82 tint: a tint fitted to a reconstruction (judge.fit_f82) moved every simulated
        # metal scan's export farther from the truth (docs/export.md, "OpenPBR Surface")
        return write_mtlx(fits.principled, out, name, prov)
    if fmt in ("gltf", "glb"):
        from gonio.export.gltf import write_glb, write_gltf

        # One document either way: JSON with the buffer embedded, or the binary container.
        writer = write_glb if fmt == "glb" else write_gltf
        return writer(fits.principled, out, name, prov, with_mesh)
    from gonio.export.merl import write_merl

    # R, G, B as the glTF and MaterialX fits hold them: linear sRGB from XYZ when the result
    # has colour (a spectral table has no R, G, B of its own; a chart-calibrated sensor's raw
    # channels are not sRGB, while the sidecar's colour_space says linear sRGB).
    return write_merl(fits.table if fits.srgb_table is None else fits.srgb_table, out, prov)


def export_warnings(fmt: str, path: str | os.PathLike[str], prov: dict[str, Any]) -> list[str]:
    """The warnings that go with an exported file, as ``gonio export`` prints them and the
    daemon sends them with a download (the ``X-Gonio-Export-Warnings`` header): the file's
    own (:func:`format_provenance`), for MERL its sidecar's (which add the anisotropy the
    azimuthal average lost).

    Parameters
    ----------
    fmt : str
        The format written.
    path : path-like
        The file written (a MERL file's sidecar is read beside it).
    prov : dict
        The provenance it was written with (:func:`result_fits`).
    """
    import json

    if fmt == "merl":
        from gonio.export.merl import sidecar_path

        side = json.loads(sidecar_path(path).read_text())
        return [str(w) for w in side.get("warnings") or []]
    return [str(w) for w in format_provenance(fmt, prov).get("warnings") or []]


def export_result(result_path: str | os.PathLike[str], fmt: str,
                  out: str | os.PathLike[str], *, with_mesh: bool = False) -> Path:
    """Export a job's result file to ``out`` in format ``fmt``; returns the path.

    ``with_mesh``: the glTF (``gltf``, ``glb``) gets a preview sphere (ignored by the other
    formats).

    Raises
    ------
    ExportError
        Unknown format, not a result file, or a result without a reconstruction.
    """
    check_format(fmt)
    fits, prov = result_fits(result_path)
    return write_export(fits, fmt, out, prov, with_mesh=with_mesh)
