"""Materials out of the lab: a job's result file in formats renderers and other tools read.

========== ========== ===================================================================
format     suffix     what
========== ========== ===================================================================
factored   ``.npz``   the factored fit of paper 000 (:mod:`gonio.brdf.models.factored`)
mtlx       ``.mtlx``  MaterialX ``standard_surface`` from the principled fit (:mod:`.mtlx`)
gltf       ``.gltf``  glTF 2.0 material with ``KHR_materials_anisotropy`` (:mod:`.gltf`)
merl       ``.binary`` MERL layout, azimuthally averaged (:mod:`.merl`)
table      ``.npz``   gonio's own BRDF table (:class:`gonio.brdf.tables.table.BRDFTable`)
========== ========== ===================================================================

The fits come from the result file (the daemon stores them when it reconstructs); a result
written before they existed is fitted here, which takes some seconds. Every format that has
room for it carries the provenance of :func:`provenance`.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from gonio.brdf.models.factored import FactoredBRDF, fit_factored
from gonio.brdf.models.principled import Principled, fit_principled
from gonio.brdf.tables.table import BRDFTable

FORMATS: dict[str, str] = {
    "factored": ".npz", "mtlx": ".mtlx", "gltf": ".gltf", "merl": ".binary", "table": ".npz",
}
MEDIA_TYPES: dict[str, str] = {
    "factored": "application/octet-stream", "mtlx": "application/xml",
    "gltf": "model/gltf+json", "merl": "application/octet-stream",
    "table": "application/octet-stream",
}
#: Iterations of the factored fit when it runs at export or reconstruction time.
FIT_ITERATIONS = 10


class ExportError(ValueError):
    """An export cannot be made; the message says why and what to do."""


@dataclass(frozen=True)
class Fits:
    """A result's table and the two fits every export format starts from."""

    table: BRDFTable
    factored: FactoredBRDF
    principled: Principled


def fit_all(table: BRDFTable) -> Fits:
    """Factored and principled fits of a reconstructed table (seconds of CPU)."""
    return Fits(table, fit_factored(table, iterations=FIT_ITERATIONS), fit_principled(table))


def check_format(fmt: str) -> str:
    """``fmt`` if it is a known format, else :class:`ExportError` listing them."""
    if fmt not in FORMATS:
        raise ExportError(f"unknown export format {fmt!r}; use one of {', '.join(FORMATS)}")
    return fmt


def result_fits(result_path: str | os.PathLike[str]) -> tuple[Fits, dict[str, Any]]:
    """The fits of a result file (stored ones, else fitted now) and its provenance."""
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
    factored = res.factored or fit_factored(res.table, iterations=FIT_ITERATIONS)
    principled = res.principled or fit_principled(res.table)
    fits = Fits(res.table, factored, principled)
    return fits, provenance(res.attrs, fits, res.metrics)


def provenance(attrs: dict[str, Any], fits: Fits, metrics: dict[str, Any]) -> dict[str, Any]:
    """What an exported file says about where it came from."""
    return {
        "generator": f"gonio {attrs.get('gonio_version', '')}".strip(),
        "job_id": attrs.get("job_id"), "specimen": attrs.get("specimen"),
        "measured": attrs.get("created"),
        "reconstruction_predicted_error": metrics.get("predicted_error"),
        "factored_fit": {k: fits.factored.metrics.get(k)
                         for k in ("rel_mse", "mape", "psnr", "log_rmse")},
        "principled_fit": {k: fits.principled.metrics.get(k)
                           for k in ("rel_mse", "mape", "psnr", "log_rmse")},
    }


def write_export(fits: Fits, fmt: str, out: str | os.PathLike[str],
                 prov: dict[str, Any]) -> Path:
    """Write one format from fits already in hand; returns the path."""
    from gonio.export.gltf import GltfError
    from gonio.export.merl import MerlError
    from gonio.export.mtlx import MtlxError

    check_format(fmt)
    try:
        return _write(fits, fmt, out, prov)
    except (MerlError, MtlxError, GltfError) as exc:
        # MerlError, MtlxError, GltfError (e.g. a table that is not R, G, B): the caller (the
        # daemon turns ExportError into a 404 with the reason) gets one error type to handle.
        raise ExportError(
            f"cannot write {fmt}: {exc}; the 'table' and 'factored' formats keep any channels"
        ) from None


def _write(fits: Fits, fmt: str, out: str | os.PathLike[str], prov: dict[str, Any]) -> Path:
    name = str(prov.get("specimen") or fits.table.name)
    if fmt == "table":
        table = BRDFTable.trusted(
            fits.table.values, fits.table.channels, fits.table.name, fits.table.wavelengths_nm,
            {**fits.table.provenance, **prov},
        )
        return table.save(out)
    if fmt == "factored":
        return fits.factored.save(out, prov)
    if fmt == "mtlx":
        from gonio.export.mtlx import write_mtlx

        return write_mtlx(fits.principled, out, name, prov)
    if fmt == "gltf":
        from gonio.export.gltf import write_gltf

        return write_gltf(fits.principled, out, name, prov)
    from gonio.export.merl import write_merl

    return write_merl(fits.table, out)


def export_result(result_path: str | os.PathLike[str], fmt: str,
                  out: str | os.PathLike[str]) -> Path:
    """Export a job's result file to ``out`` in format ``fmt``; returns the path.

    Raises
    ------
    ExportError
        Unknown format, not a result file, or a result without a reconstruction.
    """
    check_format(fmt)
    fits, prov = result_fits(result_path)
    return write_export(fits, fmt, out, prov)
