"""A job's result file as the service serves it: found, checked, read once, kept, rendered.

Every read of a result file for serving goes through :class:`ResultViews`: one cache of opened
files (:class:`gonio.results.ResultCache`), the last few preview and rendering PNGs (finished
result files never change; each entry is keyed by the file's modification time), and the exports
kept on disk under ``data_dir/exports``. A missing or damaged file is never served as if it were
good: the error names the job and how to rebuild it from the job store.
"""

from __future__ import annotations

import threading
from pathlib import Path
from typing import TYPE_CHECKING, Any

from gonio.jobstates import JobState
from gonio.service_models import NotFound, job_row
from gonio.store import JobStore

if TYPE_CHECKING:  # HDF5 and the figures load with the first result served
    from gonio.results import ResultCache, ResultFile

_PREVIEW_CACHE = 8
"""Preview PNGs kept in memory (a few tens of kB each)."""
_RENDER_CACHE = 3
"""Rendered figures kept in memory (about 1-3 MB each): the job on the page, the one it is
compared with, one more. More kept the daemon growing for six scans (bench/bench_memory.py)."""


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
        self._previews: dict[tuple[str, int], bytes] = {}
        self._renders: dict[tuple[Any, ...], bytes] = {}
        # Made on first use: HDF5 loads with it.
        self._result_cache: ResultCache | None = None

    def result_path(self, job_id: int) -> Path:
        """Where job ``job_id``'s result file is: the store's path, relative to the data
        directory (an absolute one, from a foreign store, is taken as it is)."""
        row = job_row(self.store, job_id)
        if not row.result_path:
            raise NotFound(f"job {job_id} has no result yet (it is {row.state.value})")
        return self.data_dir / row.result_path

    def rebuild_hint(self, job_id: int) -> str:
        """What to do about a job whose result file is missing or damaged."""
        return (f"rebuild it from the readings the job store holds: gonio jobs rebuild "
                f"{job_id} --db {self.store.path}")

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
            raise NotFound(f"job {job_id} has no result yet (it is {row.state.value})")
        from gonio.figures import headline_error

        out = dict(row.summary)
        # The one error number to show, with its meaning (the same words as `gonio scan`).
        out["headline_error"] = headline_error(out)
        return out

    def result(self, job_id: int) -> ResultFile:
        """A job's result file, read whole; the last few are kept (:class:`ResultCache`).

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

        path = self.result_path(job_id)
        if not path.is_file():
            raise NotFound(f"job {job_id}'s result file {path.name} is missing from the data "
                           f"directory; {self.rebuild_hint(job_id)}")
        try:
            return self._results().get(path)
        except ResultFileError as exc:
            raise ResultFileError(f"job {job_id}'s result file is damaged: {exc}; "
                                  f"{self.rebuild_hint(job_id)}") from None

    def _results(self) -> ResultCache:
        with self._lock:
            if self._result_cache is None:
                from gonio.results import ResultCache

                # Two: a job and the one it is compared with (a table is 5-10 MB in memory).
                self._result_cache = ResultCache(size=2)
            return self._result_cache

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
        PNG of the last few results is kept, since a finished result file never changes.

        Raises
        ------
        NotFound
            The job has no result yet, or it is a calibration job (no BRDF).
        """
        path = self.result_path(job_id)
        key = (str(path), path.stat().st_mtime_ns if path.is_file() else 0)
        with self._lock:
            cached = self._previews.get(key)
        if cached is not None:
            return cached
        res = self.result(job_id)
        if res.table is None:
            raise NotFound(f"job {job_id} is a {res.attrs.get('kind')} job without a BRDF")
        from gonio.brdf.pictures.preview import preview_png

        png = preview_png(res.table, title=f"job {job_id}: {res.table.name}")
        with self._lock:
            self._previews[key] = png
            while len(self._previews) > _PREVIEW_CACHE:
                self._previews.pop(next(iter(self._previews)))
        return png

    def export(self, job_id: int, fmt: str, with_mesh: bool = False) -> tuple[Path, str]:
        """A job's result exported as ``fmt`` (:mod:`gonio.export`): file path and file name.

        Blocking (may fit and resample for seconds): call it from a thread in async code.
        Exports are kept under ``data_dir/exports`` and reused while the result file is
        unchanged. ``with_mesh`` adds the glTF's preview sphere (``gonio export --with-mesh``),
        a file of its own (``...-gltf-mesh.gltf``).

        Raises
        ------
        NotFound
            The job has no result yet, or its result has no BRDF (a calibration job).
        ExportError
            ``with_mesh`` for a format other than glTF.
        """
        from gonio.export import FORMATS, ExportError, check_format, export_result

        check_format(fmt)
        if with_mesh and fmt != "gltf":
            raise ExportError(f"with_mesh applies to format gltf only, not {fmt!r}; leave "
                              "with_mesh out or ask for format=gltf")
        path = self.result_path(job_id)
        self.result(job_id)  # missing or damaged: said with the way to rebuild it
        name = f"gonio-job-{job_id}-{fmt}{'-mesh' if with_mesh else ''}{FORMATS[fmt]}"
        out = self.data_dir / "exports" / name
        if out.is_file() and out.stat().st_mtime_ns >= path.stat().st_mtime_ns:
            return out, name
        out.parent.mkdir(parents=True, exist_ok=True)
        try:
            export_result(path, fmt, out, with_mesh=with_mesh)
        except ExportError as exc:
            raise NotFound(f"job {job_id}: {exc}") from None
        return out, name

    def render_png(self, job_id: int, compare: int | None = None) -> bytes:
        """Rendering of a job's reconstruction (:func:`gonio.figures.render_inputs`).

        With ``compare``, that job's reconstruction is shown below for comparison; without,
        the true material above it when the result records one (simulated rig). Blocking
        (seconds: it renders six views per material): call it from a thread. The last few
        PNGs are kept, since finished result files never change.

        Raises
        ------
        NotFound
            A job has no result yet, or it is a calibration job (no BRDF).
        """
        from gonio.figures import FigureError, render_inputs

        paths = [self.result_path(job_id)]
        if compare is not None:
            paths.append(self.result_path(compare))
        key = ("render", *((str(p), p.stat().st_mtime_ns if p.is_file() else 0) for p in paths))
        with self._lock:
            cached = self._renders.get(key)
        if cached is not None:
            return cached
        ids = [job_id] if compare is None else [job_id, compare]
        for jid in ids:
            self.result(jid)  # missing or damaged: said with the way to rebuild it
        try:
            png = render_inputs(paths)
        except FigureError as exc:
            raise NotFound(str(exc).replace(str(paths[0]), f"job {job_id}")) from None
        with self._lock:
            self._renders[key] = png
            while len(self._renders) > _RENDER_CACHE:
                self._renders.pop(next(iter(self._renders)))
        return png
