"""A job's result file as the service serves it: found, checked, read once, kept, rendered.

Every read of a result file for serving goes through :class:`ResultViews`, and so does every
view computed from one (the fit and polar plots' curves, the preview and rendering PNGs): both
are kept in one cache keyed by the file's identity on disk (:mod:`gonio.result_cache`), so a
view is computed once while its file stays the same and never outlives it (``gonio jobs
rebuild`` replaces the file: the next request reads the new one). Exports are kept on disk under
``data_dir/exports``. A missing or damaged file is never served as if it were good: the error
names the job and how to rebuild it from the job store.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar

from gonio.jobstates import FINISHED_STATES, JobState
from gonio.service_models import NotFound, job_row
from gonio.store import JobRow, JobStore

if TYPE_CHECKING:  # HDF5 and the figures load with the first result served
    from gonio.result_cache import ResultCache
    from gonio.results import ResultFile

T = TypeVar("T")


def download_stem(job_id: int, specimen: str | None) -> str:
    """The start of the name of a job's downloads (its result, its exports):
    ``gonio-job-7-brushed-steel``, the specimen's name made safe for a file name (ASCII
    letters, digits and ``-_.``; other characters as ``-``; at most 60 of them), left out
    when nothing of it remains.

    Parameters
    ----------
    job_id : the job
    specimen : its specimen name (the plan's)

    Returns
    -------
    str
        ``gonio-job-<id>`` or ``gonio-job-<id>-<specimen>``.
    """
    import re
    import unicodedata

    ascii_name = unicodedata.normalize("NFKD", specimen or "").encode("ascii", "ignore").decode()
    safe = re.sub(r"[^A-Za-z0-9_.]+", "-", ascii_name).strip("-._")[:60].rstrip("-._")
    return f"gonio-job-{job_id}-{safe}" if safe else f"gonio-job-{job_id}"


def warnings_path(export: Path) -> Path:
    """Where :meth:`ResultViews.export` keeps an export's warnings: ``<file>.warnings.json``."""
    return export.with_name(export.name + ".warnings.json")


def _no_result(row: JobRow) -> str:
    """Why job ``row`` has no result: still on its way, or ended without one (an aborted job
    was said to have "no result yet", which promises one)."""
    if row.state in FINISHED_STATES:
        why = f": {row.reason}" if row.reason else ""
        return f"job {row.id} ended {row.state.value}{why}, without a result"
    return f"job {row.id} has no result yet (it is {row.state.value})"


class ResultViews:
    """The results of one job store's jobs, read for serving.

    Parameters
    ----------
    store : JobStore
        Where the jobs and their result paths are.
    data_dir : Path
        The data directory result paths are relative to (absolute).
    """

    def __init__(self, store: JobStore, data_dir: Path) -> None:
        self.store = store
        self.data_dir = data_dir
        self._lock = threading.Lock()
        # Made on first use: HDF5 loads with it.
        self._cache: ResultCache | None = None

    def result_path(self, job_id: int) -> Path:
        """Where job ``job_id``'s result file is: the store's path, relative to the data
        directory (an absolute one, from a foreign store, is taken as it is)."""
        row = job_row(self.store, job_id)
        if not row.result_path:
            raise NotFound(_no_result(row))
        return self.data_dir / row.result_path

    def rebuild_hint(self, job_id: int) -> str:
        """What to do about a job whose result file is missing or damaged."""
        from gonio.finishing import rebuild_command

        return ("rebuild it from the readings the job store holds: "
                + rebuild_command(job_id, self.store.path, self.data_dir))

    def checked_result_path(self, job_id: int) -> Path:
        """Job ``job_id``'s result file, once it has been read whole (and kept in the cache),
        so a truncated or damaged file is never served as if it were good.

        Blocking (reads the file): call it from a thread in async code.

        Raises
        ------
        NotFound
            No such job, no result yet, or the file is missing.
        gonio.results.ResultFileError
            The file is damaged; the message names the job and how to rebuild it.
        """
        self.result(job_id)
        return self.result_path(job_id)

    def damaged_results(self) -> list[str]:
        """One line per completed job whose result file is missing or damaged
        (:func:`gonio.results.check_result_file`, cheap: no dataset is read whole)."""
        from gonio.results import ResultFileError, check_result_file

        out = []
        for row in self.store.list_jobs([JobState.COMPLETED.value]):
            if not row.result_path:
                continue
            try:
                check_result_file(self.data_dir / row.result_path)
            except ResultFileError as exc:
                out.append(f"job {row.id}: {exc}; {self.rebuild_hint(row.id)}")
        return out

    def metrics(self, job_id: int) -> dict[str, Any]:
        row = job_row(self.store, job_id)
        if row.summary is None:
            raise NotFound(_no_result(row))
        from gonio.figures import headline_error

        out = dict(row.summary)
        # The one error number to show, with its meaning (the same words as `gonio scan`).
        out["headline_error"] = headline_error(out)
        return out

    def result(self, job_id: int) -> ResultFile:
        """A job's result file, read whole; the last few are kept
        (:class:`gonio.result_cache.ResultCache`).

        Blocking (reads the file): call it from a thread in async code.

        Raises
        ------
        NotFound
            No such job, or it has no result yet.
        gonio.results.ResultFileError
            The file cannot be read (damaged, truncated); the message names the job and
            how to rebuild it.
        """
        from gonio.results import ResultFileError

        path = self._existing_path(job_id)
        try:
            return self.cache.result(path)
        except ResultFileError as exc:
            if not path.is_file():  # removed while it was being read
                self._existing_path(job_id)
            raise ResultFileError(f"job {job_id}'s result file is damaged: {exc}; "
                                  f"{self.rebuild_hint(job_id)}") from None

    @property
    def cache(self) -> ResultCache:
        """The cache of result files and their views (:mod:`gonio.result_cache`)."""
        with self._lock:
            if self._cache is None:
                from gonio.result_cache import ResultCache

                self._cache = ResultCache()
            return self._cache

    def _existing_path(self, job_id: int) -> Path:
        """Job ``job_id``'s result file, which must be there.

        Raises
        ------
        NotFound
            No such job, no result yet, or the file is missing (with how to rebuild it).
        """
        path = self.result_path(job_id)
        if not path.is_file():
            raise NotFound(f"job {job_id}'s result file {path.name} is missing from the data "
                           f"directory; {self.rebuild_hint(job_id)}")
        return path

    def _view(self, name: str, params: tuple[Any, ...], job_ids: list[int],
              make: Callable[[], T]) -> T:
        """A view of the result files of ``job_ids`` (:meth:`ResultCache.view`): made once
        while the files stay the same; a missing one is said as :meth:`result` says it."""
        from gonio.results import ResultFileError

        paths = [self._existing_path(j) for j in job_ids]
        try:
            return self.cache.view(name, params, paths, make)
        except ResultFileError:
            for j in job_ids:  # removed between the check and the view: NotFound, as above
                self._existing_path(j)
            raise

    def reconstruction(self, job_id: int) -> ResultFile:
        """A job's result file that holds a reconstructed BRDF (for the plots of the page).

        Raises
        ------
        NotFound
            No such job, no result yet, the file is missing, or it has no BRDF (calibration).
        """
        res = self.result(job_id)
        if res.table is None:
            raise NotFound(f"job {job_id} has no reconstructed BRDF (a calibration job has none)")
        return res

    def preview_png(self, job_id: int) -> bytes:
        """PNG preview of the reconstructed table (:func:`gonio.brdf.pictures.preview.preview_png`).

        Blocking (reads the result file, renders): call it from a thread in async code. The
        PNG is kept while the result file stays the same (:attr:`cache`).

        Raises
        ------
        NotFound
            The job has no result yet, or it is a calibration job (no BRDF).
        """
        def make() -> bytes:
            res = self.result(job_id)
            if res.table is None:
                raise NotFound(f"job {job_id} is a {res.attrs.get('kind')} job without a BRDF")
            from gonio.brdf.pictures.preview import preview_png
            from gonio.result_colour import linear_srgb

            # A result with colour (spectral bands, a chart calibration) is shown in linear
            # sRGB from XYZ, as its renderings are; its first three channels (a 31-band
            # table's 400-420 nm) drew a red paint grey.
            srgb = linear_srgb(res)
            table = res.table if srgb is None else srgb[0]
            return preview_png(table, title=f"job {job_id}: {res.table.name}")

        return self._view("preview", (job_id,), [job_id], make)

    def fit_curves(self, job_id: int) -> dict[str, Any]:
        """Each pair's samples against stage angle and the reconstruction's curve through
        them (:func:`gonio.figures.fit_curves`), computed once while the file stays the same.

        Blocking (reads the result file, evaluates the table): call it from a thread in async
        code. The dict is shared: callers must not change it.

        Raises
        ------
        NotFound
            The job has no result yet, its file is missing, or it has no BRDF (calibration).
        gonio.results.ResultFileError
            The file is damaged; the message names the job and how to rebuild it.
        """
        from gonio.figures import fit_curves

        return self._view("fit", (job_id,), [job_id],
                          lambda: fit_curves(self.reconstruction(job_id)))

    def polar_curves(self, job_id: int, theta_i_deg: float, phi_i_deg: float) -> dict[str, Any]:
        """In-plane and cross-plane BRDF at one incidence
        (:func:`gonio.figures.polar_curves`), computed once per incidence while the file
        stays the same. Blocking, shared and raising as :meth:`fit_curves`."""
        from gonio.figures import polar_curves

        return self._view("polar", (job_id, float(theta_i_deg), float(phi_i_deg)), [job_id],
                          lambda: polar_curves(self.reconstruction(job_id), theta_i_deg,
                                               phi_i_deg))

    def export(self, job_id: int, fmt: str, with_mesh: bool = False) -> tuple[Path, str]:
        """A job's result exported as ``fmt`` (:mod:`gonio.export`): file path and file name.

        Blocking (may fit and resample for seconds): call it from a thread in async code.
        Exports are kept under ``data_dir/exports`` and reused while the result file is
        unchanged, each with its warnings beside it (:meth:`export_warnings`; an export kept
        without them is made again). ``with_mesh`` adds the glTF's preview sphere (``gonio
        export --with-mesh``; ``gltf`` and ``glb``), a file of its own (``...-gltf-mesh.gltf``,
        ``...-glb-mesh.glb``). The file name starts
        with the job and its specimen (:func:`download_stem`).

        Raises
        ------
        NotFound
            The job has no result yet, or its result has no BRDF (a calibration job).
        ExportError
            ``with_mesh`` for a format other than glTF (``gltf``, ``glb``).
        """
        import json

        from gonio.atomicfile import write_atomically
        from gonio.export import (
            FORMATS,
            MESH_FORMATS,
            ExportError,
            check_format,
            export_warnings,
            result_fits,
            write_export,
        )
        from gonio.export.child import run_fits

        check_format(fmt)
        if with_mesh and fmt not in MESH_FORMATS:
            raise ExportError(f"with_mesh applies to format {' or '.join(MESH_FORMATS)} only, "
                              f"not {fmt!r}; leave with_mesh out or ask for format=gltf or "
                              "format=glb")
        path = self.result_path(job_id)
        self.result(job_id)  # missing or damaged: said with the way to rebuild it
        stem = download_stem(job_id, job_row(self.store, job_id).specimen)
        name = f"{stem}-{fmt}{'-mesh' if with_mesh else ''}{FORMATS[fmt]}"
        out = self.data_dir / "exports" / name
        warned = warnings_path(out)
        if (out.is_file() and warned.is_file()
                and out.stat().st_mtime_ns >= path.stat().st_mtime_ns):
            return out, name
        out.parent.mkdir(parents=True, exist_ok=True)
        try:
            # In a fresh interpreter when the daemon's heap is bounded: half the CPU
            # (gonio.export.child).
            fits, prov = run_fits(result_fits, path)
            write_export(fits, fmt, out, prov, with_mesh=with_mesh)
        except ExportError as exc:
            raise NotFound(f"job {job_id}: {exc}") from None
        # What `gonio export` would print as warnings, kept for the download's header.
        write_atomically(warned, json.dumps(export_warnings(fmt, out, prov)))
        return out, name

    @staticmethod
    def export_warnings(out: Path) -> list[str]:
        """The warnings of an export :meth:`export` made (its path): what ``gonio export``
        prints for the same file, e.g. that a MERL file lost the result's anisotropy."""
        import json

        return [str(w) for w in json.loads(warnings_path(out).read_text())]

    def render_png(self, job_id: int, compare: int | None = None) -> bytes:
        """Rendering of a job's reconstruction (:func:`gonio.figures.render_inputs`).

        With ``compare``, that job's reconstruction is shown below for comparison; without,
        the true material above it when the result records one (simulated rig). Blocking
        (seconds: it renders six views per material): call it from a thread. The PNG is kept
        while the result files stay the same (:attr:`cache`), and the files are not read again
        for it.

        Raises
        ------
        NotFound
            A job has no result yet, or it is a calibration job (no BRDF).
        """
        from gonio.figures import FigureError, render_inputs

        ids = [job_id] if compare is None else [job_id, compare]

        def make() -> bytes:
            # Missing, damaged or without a BRDF: said with the job (and how to rebuild it).
            results = [self.reconstruction(jid) for jid in ids]
            try:
                return render_inputs(results)
            except FigureError as exc:
                raise NotFound(f"job {job_id}: {exc}") from None

        return self._view("render", tuple(ids), ids, make)
