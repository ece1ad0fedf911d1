"""The result file of a finished job: one HDF5 file (h5py) with a documented layout.

Layout (also in ``docs/engine.md``; strings are UTF-8, JSON attributes are strings)::

    /                         attrs: format="gonio-result", version=1, gonio_version, job_id,
                                     specimen, kind, created (ISO 8601 UTC)
    /raw                      one row per (stage angle, light, sensor) reading, m rows
        angle_index (m,) i8   commanded_deg (m,) f8   actual_deg (m,) f8
        light (m,) str        sensor (m,) str
        raw (m, C) f8         dark (m, C) f8          sensor units
        exposure_s (m,) f8    averages (m,) i8        saturated (m,) bool   t_read (m,) f8 (Unix s)
        range_index (m,) i8   range_scale (m,) f8     sensor range of each reading (0: nominal)
                              and its sensitivity relative to range 0; dark read in that range
                              (absent in files written before auto-ranging: all range 0)
    /samples                  calibrated samples the reconstruction used
        channels (C,) str     pairs (n, 2) str (light, sensor)
        light_dirs (n, 3) f8  sensor_dirs (n, 3) f8   lab-frame unit vectors
        stage_angles_deg (r,) f8                      specimen rotation of each column
        values (n, r, C) f8   BRDF, 1/sr (sensor units if uncalibrated, see calibration attr)
        attrs: calibration (JSON)
    /reconstruction           absent for calibration jobs
        values (C, 72, 18, 18, 36) f4   f[c, i_ph, i_th, i_td, i_pd], 1/sr, NaN = invalid cell
        channels (C,) str     coefficients (C, K, 72) f8
        wavelengths_nm (C,) f8                        spectral sensors only: band centres
        attrs: rel_sample_error, estimated_error (fractions), settings (JSON)
    /colour                   absent before colour existed; see docs/colour.md
        attrs: source (JSON: how channels become XYZ: {"bands": ...}, {"calibration": ...}
               or {} for uncalibrated sensor RGB), report (JSON: the colour report at the
               default instruments under D65/10, written when the job finished)
    /factored                 the factored fit of the reconstruction
                              (000; gonio.brdf.models.factored)
        rho_d (C,) rho_s (C,) D (18, 72) F (C, 18) G (19, 72) f8, channels (C,) str,
        D_theta_h_deg, D_phi_h_deg, F_theta_d_deg, G_theta_deg, G_phi_deg (grids)
        attrs: metrics (JSON: rel_mse, mape, psnr, log_rmse, iterations, seconds)
    /principled               attrs: params (JSON, gonio.brdf.models.principled.Principled.as_dict)
    /metrics                  attrs: one float or string per metric
    /provenance               attrs: plan, rig, rig_config, calibration (JSON),
                                     basis_K, basis_materials (JSON list), and when they
                                     apply calibration_warning, arc_warning

Read back with :func:`read_result` (the provenance alone, of any version: :func:`read_provenance`).
"""

from __future__ import annotations

import json
import logging
import os
import threading
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import h5py
import numpy as np
from numpy.typing import NDArray

from gonio import __version__
from gonio.atomicfile import write_atomically
from gonio.brdf.models.factored import FactoredBRDF
from gonio.brdf.models.principled import Principled
from gonio.brdf.tables.npzfile import HDF5_MAGIC
from gonio.brdf.tables.table import BRDFTable
from gonio.calibration import CalibratedScan
from gonio.store import ReadingRow
from gonio.wording import DAMAGED

FORMAT_NAME = "gonio-result"
FORMAT_VERSION = 1

_log = logging.getLogger(__name__)


class ResultFileError(ValueError):
    """A result file is missing, not a gonio result, or of an unknown version."""


class OffGridAngle(ValueError):
    """A query of a result at an angle that is not on the result's 5 degree grid; the message
    says which angles are."""


@dataclass
class ResultFile:
    """Everything in a result file, loaded."""

    attrs: dict[str, Any]
    readings: list[ReadingRow]
    samples: CalibratedScan
    table: BRDFTable | None
    rel_sample_error: float | None
    estimated_error: float | None
    settings: dict[str, Any]
    metrics: dict[str, Any]
    provenance: dict[str, Any]
    factored: FactoredBRDF | None = None
    principled: Principled | None = None
    #: The ``/colour`` group's attributes, JSON decoded ({} when the file has none).
    colour: dict[str, Any] | None = None


_STR = h5py.string_dtype("utf-8")


def _strs(values: Sequence[str]) -> NDArray[Any]:
    return np.asarray(list(values), dtype=object)


def write_result(
    path: str | os.PathLike[str],
    *,
    job_id: int,
    specimen: str,
    kind: str,
    readings: Sequence[ReadingRow],
    samples: CalibratedScan,
    table: BRDFTable | None = None,
    coefficients: NDArray[np.float64] | None = None,
    rel_sample_error: float | None = None,
    estimated_error: float | None = None,
    settings: Mapping[str, Any] | None = None,
    metrics: Mapping[str, Any] | None = None,
    provenance: Mapping[str, Any] | None = None,
    factored: FactoredBRDF | None = None,
    principled: Principled | None = None,
    colour: Mapping[str, Any] | None = None,
) -> Path:
    """Write a result file atomically (to a temporary name, then renamed). Returns the path.

    ``colour`` holds the ``/colour`` group's attributes (each stored as JSON).

    The HDF5 file is built in memory and its bytes written with plain file I/O: HDF5 never
    writes to the disk itself. A disk that fills during HDF5's own writes left an open file
    the library could neither flush nor close, and the process crashed (SIGSEGV) when that
    state was torn down; a failed plain write is an ``OSError`` and nothing else.

    Raises
    ------
    OSError
        The file could not be written (``errno`` ``ENOSPC`` for a full disk); no file and
        no ``.part`` file is left behind.
    """
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    image = _result_image(
        job_id=job_id, specimen=specimen, kind=kind, readings=readings, samples=samples,
        table=table, coefficients=coefficients, rel_sample_error=rel_sample_error,
        estimated_error=estimated_error, settings=settings, metrics=metrics,
        provenance=provenance, factored=factored, principled=principled, colour=colour)
    return write_atomically(out, image)


def _result_image(
    *,
    job_id: int,
    specimen: str,
    kind: str,
    readings: Sequence[ReadingRow],
    samples: CalibratedScan,
    table: BRDFTable | None,
    coefficients: NDArray[np.float64] | None,
    rel_sample_error: float | None,
    estimated_error: float | None,
    settings: Mapping[str, Any] | None,
    metrics: Mapping[str, Any] | None,
    provenance: Mapping[str, Any] | None,
    factored: FactoredBRDF | None,
    principled: Principled | None,
    colour: Mapping[str, Any] | None = None,
) -> bytes:
    """The bytes of a result file (the layout above), built in memory by HDF5's core
    driver without a backing store."""
    # The name only labels the in-memory file; nothing is created under it.
    f = h5py.File(f"gonio-result-{job_id}-{threading.get_ident()}.h5", "w", driver="core",
                  backing_store=False)
    with f:
        f.attrs.update({
            "format": FORMAT_NAME, "version": FORMAT_VERSION, "gonio_version": __version__,
            "job_id": job_id, "specimen": specimen, "kind": kind,
            "created": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        })
        g = f.create_group("raw")
        nch = max((len(r.raw) for r in readings), default=len(samples.channels))
        g["angle_index"] = np.asarray([r.angle_index for r in readings], dtype=np.int64)
        g["commanded_deg"] = np.asarray([r.commanded_deg for r in readings], dtype=float)
        g["actual_deg"] = np.asarray([r.actual_deg for r in readings], dtype=float)
        g.create_dataset("light", data=_strs([r.light for r in readings]), dtype=_STR)
        g.create_dataset("sensor", data=_strs([r.sensor for r in readings]), dtype=_STR)
        g["raw"] = np.asarray([r.raw for r in readings], dtype=float).reshape(-1, nch)
        g["dark"] = np.asarray([r.dark for r in readings], dtype=float).reshape(-1, nch)
        g["exposure_s"] = np.asarray([r.exposure_s for r in readings], dtype=float)
        g["averages"] = np.asarray([r.averages for r in readings], dtype=np.int64)
        g["saturated"] = np.asarray([r.saturated for r in readings], dtype=bool)
        g["t_read"] = np.asarray([r.t_read for r in readings], dtype=float)
        g["range_index"] = np.asarray([r.range_index for r in readings], dtype=np.int64)
        g["range_scale"] = np.asarray([r.range_scale for r in readings], dtype=float)

        s = f.create_group("samples")
        s.create_dataset("channels", data=_strs(samples.channels), dtype=_STR)
        s.create_dataset("pairs", data=np.asarray(
            [[a, b] for a, b in samples.pairs], dtype=object).reshape(-1, 2), dtype=_STR)
        s["light_dirs"] = np.asarray(samples.light_dirs, dtype=float).reshape(-1, 3)
        s["sensor_dirs"] = np.asarray(samples.sensor_dirs, dtype=float).reshape(-1, 3)
        s["stage_angles_deg"] = np.asarray(samples.stage_angles_deg, dtype=float)
        s["values"] = np.asarray(samples.values, dtype=float)
        s.attrs["calibration"] = json.dumps(samples.calibration)

        if table is not None:
            r = f.create_group("reconstruction")
            r.create_dataset("values", data=np.asarray(table.values, dtype=np.float32),
                             compression="gzip", compression_opts=4, shuffle=True)
            r.create_dataset("channels", data=_strs(table.channels), dtype=_STR)
            if coefficients is not None:
                r["coefficients"] = np.asarray(coefficients, dtype=float)
            if table.wavelengths_nm is not None:
                r["wavelengths_nm"] = np.asarray(table.wavelengths_nm, dtype=float)
            r.attrs["rel_sample_error"] = float(rel_sample_error or 0.0)
            r.attrs["estimated_error"] = float(estimated_error or 0.0)
            r.attrs["settings"] = json.dumps(dict(settings or {}), default=str)
            r.attrs["name"] = table.name

        if colour is not None:
            c = f.create_group("colour")
            for k, v in colour.items():
                c.attrs[k] = json.dumps(v, default=str)
        if factored is not None:
            write_factored_group(f, factored)
        if principled is not None:
            f.create_group("principled").attrs["params"] = json.dumps(principled.as_dict())
        m = f.create_group("metrics")
        for k, v in (metrics or {}).items():
            m.attrs[k] = v if isinstance(v, int | float | str) else json.dumps(v, default=str)
        p = f.create_group("provenance")
        for k, v in (provenance or {}).items():
            p.attrs[k] = v if isinstance(v, int | float | str) else json.dumps(v, default=str)
        f.flush()
        return bytes(f.id.get_file_image())


def write_factored_group(f: h5py.File, model: FactoredBRDF) -> None:
    """The ``/factored`` group of the layout above."""
    g = f.create_group("factored")
    for key, arr in model.arrays().items():
        if key == "channels":
            g.create_dataset(key, data=_strs(model.channels), dtype=_STR)
        else:
            g[key] = np.asarray(arr, dtype=float)
    g.attrs["metrics"] = json.dumps(dict(model.metrics), default=str)
    g.attrs["name"] = model.name


def _read_fits(f: h5py.File) -> tuple[FactoredBRDF | None, Principled | None]:
    """The stored fits; a damaged fit group reads as absent (with a warning), since the fits
    can be made again from the reconstruction and must not make the whole result unreadable."""
    factored = principled = None
    if "factored" in f:
        try:
            g = f["factored"]
            ga = _attr_dict(g.attrs)
            data = {k: g[k][()] for k in g}
            data["channels"] = np.asarray(_decode(g["channels"][()]))
            factored = FactoredBRDF.from_arrays(
                data, str(ga.get("name", "")), json.loads(ga.get("metrics", "{}")))
        except (KeyError, TypeError, ValueError, AttributeError) as exc:
            _log.warning("%s: /factored is damaged (%r); ignoring it", f.filename, exc)
    if "principled" in f:
        try:
            principled = Principled.from_dict(
                json.loads(_attr_dict(f["principled"].attrs)["params"]))
        except (KeyError, TypeError, ValueError, AttributeError) as exc:
            _log.warning("%s: /principled is damaged (%r); ignoring it", f.filename, exc)
    return factored, principled


def _decode(a: Any) -> list[str]:
    return [x.decode() if isinstance(x, bytes) else str(x) for x in np.asarray(a).ravel()]


def _attr_dict(attrs: h5py.AttributeManager) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for k, v in attrs.items():
        if isinstance(v, bytes):
            v = v.decode()
        if isinstance(v, np.generic):
            v = v.item()
        out[k] = v
    return out


def read_result(path: str | os.PathLike[str]) -> ResultFile:
    """Load a result file written by :func:`write_result`.

    Raises
    ------
    ResultFileError
    """
    p = Path(path)
    if not p.is_file():
        raise ResultFileError(f"result file {p} does not exist")
    try:
        f = h5py.File(p, "r")
    except OSError as exc:
        raise ResultFileError(_unopenable(p, exc)) from None
    try:
        with f:
            return _read_open(p, f)
    except (OSError, KeyError, ValueError, TypeError, IndexError) as exc:
        if isinstance(exc, ResultFileError):
            raise
        # A truncated or overwritten file can open and still fail on a dataset or attribute:
        # the words of a damaged HDF5 file, so the command line adds what to do about it.
        raise ResultFileError(f"{p}{DAMAGED} ({type(exc).__name__}: {exc})") from None


def read_provenance(path: str | os.PathLike[str]) -> dict[str, Any]:
    """The ``/provenance`` attributes of a result file, of any format version: what the gonio
    that wrote it recorded (e.g. the rig config ``gonio jobs rebuild`` needs for a job
    finished by a gonio whose job store did not keep it). Nothing else is read.

    Raises
    ------
    ResultFileError
        Missing, not HDF5, damaged, not a gonio result or without ``/provenance``; the message
        says which.
    """
    p = Path(path)
    if not p.is_file():
        raise ResultFileError(f"result file {p} does not exist")
    try:
        with h5py.File(p, "r") as f:
            if _attr_dict(f.attrs).get("format") != FORMAT_NAME:
                raise ResultFileError(f"{p} is not a gonio result file")
            if "provenance" not in f:
                raise ResultFileError(f"{p} has no /provenance group")
            return _attr_dict(f["provenance"].attrs)
    except ResultFileError:
        raise
    except (OSError, KeyError, ValueError, TypeError) as exc:
        raise ResultFileError(f"{p} is damaged ({exc})") from None


def check_result_file(path: str | os.PathLike[str]) -> None:
    """Whether ``path`` is a whole gonio result file, cheaply (no dataset is read whole).

    HDF5 checks at open that the file is as long as its superblock says (a truncated file
    fails there); then the format, version and the groups every result has are checked.

    Raises
    ------
    ResultFileError
        Missing, truncated, damaged or not a gonio result; the message says which.
    """
    p = Path(path)
    if not p.is_file():
        raise ResultFileError(f"result file {p} does not exist")
    try:
        with h5py.File(p, "r") as f:
            _check_format(p, _attr_dict(f.attrs))
            for group in ("raw", "samples", "metrics", "provenance"):
                if group not in f:
                    raise ResultFileError(f"{p} is damaged: its /{group} group is missing")
            f["samples"]["values"].shape  # noqa: B018 (reads the dataset's header)
    except ResultFileError:
        raise
    except (OSError, KeyError, ValueError, TypeError) as exc:
        raise ResultFileError(f"{p} is damaged or truncated ({exc})") from None


#: What a result file is, for the messages about a file that is not one.
_WHAT_A_RESULT_IS = ("a result is the HDF5 file 'gonio scan -o' writes, the page's "
                     "'Download HDF5 result', or DATA_DIR/results/job-N.h5")
#: The HDF5 signature, at 0 or at a power of two from 512 on (a user block before it).


def _unopenable(p: Path, exc: OSError) -> str:
    """Why h5py could not open ``p``, in the user's terms: a file of another kind (a .npz
    table, a rig config, a picture) is not called damaged, and a damaged HDF5 file is."""
    try:
        with p.open("rb") as f:
            head = f.read(8)
            signed = head == HDF5_MAGIC
            for at in (512, 1024, 2048, 4096):
                if signed:
                    break
                f.seek(at)
                signed = f.read(8) == HDF5_MAGIC
    except OSError:
        return f"{p} cannot be read ({exc})"
    if signed:
        return f"{p}{DAMAGED} ({exc})"
    if head.startswith(b"PK\x03\x04"):
        return (f"{p} is a .npz archive (a gonio table or samples file), not a scan's result "
                f"file; {_WHAT_A_RESULT_IS}")
    return f"{p} is not an HDF5 file, so not a gonio result file; {_WHAT_A_RESULT_IS}"


def _check_format(p: Path, attrs: dict[str, Any]) -> None:
    if attrs.get("format") is None:
        raise ResultFileError(f"{p} is an HDF5 file but not a gonio result file (it has no "
                              f"'format' attribute); {_WHAT_A_RESULT_IS}")
    if attrs.get("format") != FORMAT_NAME:
        raise ResultFileError(
            f"{p} is not a gonio result file (format {attrs.get('format')!r})"
        )
    if int(attrs.get("version", -1)) != FORMAT_VERSION:
        raise ResultFileError(
            f"{p} is result format version {attrs.get('version')}, this gonio reads "
            f"{FORMAT_VERSION}; use a matching gonio version"
        )


def _read_open(p: Path, f: h5py.File) -> ResultFile:
    """The body of :func:`read_result` on the opened file."""
    attrs = _attr_dict(f.attrs)
    _check_format(p, attrs)
    g = f["raw"]
    lights, sensors = _decode(g["light"][()]), _decode(g["sensor"][()])
    # Files from before auto-ranging have every reading in range 0.
    range_index = g["range_index"][()] if "range_index" in g else np.zeros(len(lights), int)
    range_scale = g["range_scale"][()] if "range_scale" in g else np.ones(len(lights))
    # Each column read whole, once: indexing an h5py dataset reading by reading is one HDF5
    # read per value (13 a reading), which made this loop most of a small result's read.
    c = {k: g[k][()] for k in ("angle_index", "commanded_deg", "actual_deg", "raw", "dark",
                               "exposure_s", "averages", "saturated", "t_read")}
    readings = [
        ReadingRow(int(c["angle_index"][i]), float(c["commanded_deg"][i]),
                   float(c["actual_deg"][i]), lights[i], sensors[i],
                   tuple(float(x) for x in c["raw"][i]), tuple(float(x) for x in c["dark"][i]),
                   float(c["exposure_s"][i]), int(c["averages"][i]), bool(c["saturated"][i]),
                   float(c["t_read"][i]), int(range_index[i]), float(range_scale[i]))
        for i in range(len(lights))
    ]
    s = f["samples"]
    pair_names = _decode(s["pairs"][()])
    samples = CalibratedScan(
        pairs=[(pair_names[2 * i], pair_names[2 * i + 1]) for i in range(len(pair_names) // 2)],
        light_dirs=s["light_dirs"][()],
        sensor_dirs=s["sensor_dirs"][()],
        stage_angles_deg=s["stage_angles_deg"][()],
        values=s["values"][()],
        channels=tuple(_decode(s["channels"][()])),
        calibration=json.loads(_attr_dict(s.attrs).get("calibration", "{}")),
    )
    table = None
    rel = est = None
    settings: dict[str, Any] = {}
    if "reconstruction" in f:
        r = f["reconstruction"]
        ra = _attr_dict(r.attrs)
        wl = r["wavelengths_nm"][()].tolist() if "wavelengths_nm" in r else None
        table = BRDFTable(r["values"][()], tuple(_decode(r["channels"][()])),
                          str(ra.get("name", attrs.get("specimen", "result"))), wl)
        rel, est = float(ra["rel_sample_error"]), float(ra["estimated_error"])
        settings = json.loads(ra.get("settings", "{}"))
    metrics = _attr_dict(f["metrics"].attrs)
    provenance = _attr_dict(f["provenance"].attrs)
    factored, principled = _read_fits(f)
    colour = _read_colour(f)
    return ResultFile(attrs, readings, samples, table, rel, est, settings, metrics, provenance,
                      factored, principled, colour)


def _read_colour(f: h5py.File) -> dict[str, Any]:
    """The ``/colour`` group's attributes; a damaged group reads as absent (with a warning):
    colour can be computed again from the reconstruction."""
    if "colour" not in f:
        return {}
    try:
        return {k: json.loads(v) for k, v in _attr_dict(f["colour"].attrs).items()}
    except (TypeError, ValueError) as exc:
        _log.warning("%s: /colour is damaged (%r); ignoring it", f.filename, exc)
        return {}
