"""The reconstruction basis of one process: loaded or built once, its symmetry, its build.

One :class:`BasisSupply` is made by whoever owns the process (the daemon, ``gonio scan``,
``gonio jobs rebuild``) and handed to the service, the worker and finishing, so that a basis is
loaded (or built, minutes on a new install) once, under one lock, whoever asks first: the
warm-up at the daemon's start, an adaptive job before its first reading, a finishing, a sampling
design. It also answers, without loading anything, what dry runs need to know: whether the next
load is a build (:meth:`BasisSupply.build_needed`), how far that build has come
(:meth:`BasisSupply.wait_report`, the job's ETA on the page) and what the basis says about half a
turn (:meth:`BasisSupply.symmetry`); and it records a job's arc warning once
(:meth:`BasisSupply.note_arc`).

Beside it, the supply holds the basis a specimen *without* twofold symmetry is reconstructed
with (:meth:`BasisSupply.asymmetric`): when an auto-arc scan's test calls its specimen
asymmetric, finishing switches to a basis whose prior along ``ph`` holds odd harmonics
(:func:`gonio.brdf.reconstruction.basis.default_basis` with ``asymmetric=True``, trained on the
library's families without twofold symmetry too; docs/science.md 7.4). It is built on first
need (minutes: :data:`gonio.plans.dryrun.ASYMMETRIC_BASIS_BUILD_S`), under a lock of its own,
and :meth:`BasisSupply.asymmetric_build_needed` says, without a load, whether that is due.

The default supply serves :func:`gonio.brdf.reconstruction.basis.default_basis`: the basis kept
in memory is the one of the cache file as it is now (a ``gonio library import`` changes that file's
name, and the next job gets the new basis). Any other supply calls its provider once (a saved
basis, tests).
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

from gonio.plans.dryrun import BasisSymmetry, arc_warning
from gonio.plans.models import AnyPlan
from gonio.store import JobStore

if TYPE_CHECKING:  # the numerics load with the first basis, not with the daemon
    from gonio.brdf.reconstruction.basis import Basis

log = logging.getLogger("gonio.basis")

BasisProvider = Callable[[], "Basis"]
"""Returns the basis to reconstruct with (may build it; slow)."""

_FileVersion = tuple[Path, int, int]
"""A cache file and its (mtime in ns, size) when it was read."""


class BasisSupply:
    """The one reconstruction basis of a process, loaded once and shared.

    Parameters
    ----------
    provider : callable returning the basis, optional
        Called once, on the first :meth:`get`. Default: the default basis
        (:func:`gonio.brdf.reconstruction.basis.default_basis`), kept while its cache file is
        unchanged, built on first use.
    asymmetric_provider : callable returning a basis with odd harmonics, optional
        Called once, on the first :meth:`asymmetric`. Default: with the default ``provider``,
        ``default_basis(asymmetric=True)``; with a provider of its own, none (a saved basis
        is used as it is, whatever the specimen).
    """

    def __init__(self, provider: BasisProvider | None = None,
                 asymmetric_provider: BasisProvider | None = None) -> None:
        self._provider = provider
        self._asymmetric_provider = asymmetric_provider
        # The asymmetric basis has a lock of its own: building it (minutes) must not hold up
        # a job that needs only the default basis.
        self._asym_lock = threading.Lock()
        self._asym: Basis | None = None
        self._asym_version: _FileVersion | None = None
        # One load or build at a time: a second caller waits for the first one's basis.
        self._load_lock = threading.Lock()
        # Guards the fields below; never held across a load (dry runs must stay fast).
        self._state_lock = threading.Lock()
        self._basis: Basis | None = None
        self._basis_version: _FileVersion | None = None
        self._seen: BasisSymmetry | None = None
        # The symmetry of the default basis' cache file, by the version it was read from: a dry
        # run reads the file once, not at every request (a few tenths of a second for K = 64).
        self._file_symmetry: tuple[_FileVersion, BasisSymmetry] | None = None
        self._arc_noted: set[int] = set()
        self._prewarm: threading.Thread | None = None
        self._asym_prewarm: threading.Thread | None = None

    @property
    def is_default(self) -> bool:
        """Whether this supply serves the default basis (which may need a build)."""
        return self._provider is None

    # ------------------------------------------------------------------ the basis
    def get(self) -> Basis:
        """The basis, loaded (or built) on the first call and kept (blocking: minutes for a
        first build; call it in a thread from async code).

        Raises whatever the provider raises (:class:`gonio.brdf.reconstruction.basis.BasisError`
        and the like); the next call tries again.
        """
        with self._load_lock:
            if self._provider is not None:
                with self._state_lock:
                    if self._basis is not None:
                        return self._basis
                basis = self._provider()
                self._keep(basis, None)
                return basis
            from gonio.brdf.reconstruction.basis import default_basis, default_basis_path

            path = default_basis_path()
            with self._state_lock:
                if self._basis is not None and self._basis_version == _version(path):
                    return self._basis
            basis = default_basis()
            self._keep(basis, _version(path))
            return basis

    def _keep(self, basis: Basis, version: _FileVersion | None) -> None:
        symmetry = BasisSymmetry.of(basis)
        with self._state_lock:
            self._basis, self._basis_version, self._seen = basis, version, symmetry
            if version is not None:
                self._file_symmetry = (version, symmetry)

    # ------------------------------------------------------------------ the asymmetric basis
    @property
    def has_asymmetric(self) -> bool:
        """Whether this supply has a basis for specimens without twofold symmetry."""
        return self.is_default or self._asymmetric_provider is not None

    def asymmetric(self) -> Basis | None:
        """The basis a specimen without twofold symmetry is reconstructed with: its prior along
        ``ph`` holds odd harmonics. Loaded (or built: minutes, the first time on an install)
        on the first call and kept while its cache file is unchanged; None when this supply has
        none (:attr:`has_asymmetric`). Blocking; call it in a thread from async code.

        Raises whatever the build raises (:class:`gonio.brdf.reconstruction.basis.BasisError`,
        :class:`gonio.brdf.materials.library.LibraryError`: an unwritable cache folder); the
        next call tries again.
        """
        if not self.has_asymmetric:
            return None
        with self._asym_lock:
            if self._asymmetric_provider is not None:
                if self._asym is None:
                    self._asym = self._asymmetric_provider()
                return self._asym
            from gonio.brdf.reconstruction.basis import default_basis, default_basis_path

            path = default_basis_path(asymmetric=True)
            if self._asym is not None and self._asym_version == _version(path):
                return self._asym
            basis = default_basis(asymmetric=True)
            self._asym, self._asym_version = basis, _version(path)
            return basis

    def prewarm_asymmetric(self) -> bool:
        """Start getting :meth:`asymmetric` in a thread of its own, unless one was started or
        this supply has none: when an auto-arc scan's test calls its specimen asymmetric, the
        build (minutes on a new install) runs while the stage reads the other half turn, and
        finishing's own :meth:`asymmetric` waits only for what is left of it. A failure is
        logged; finishing's call tries again and reports it with the job.

        Returns
        -------
        bool
            Whether a thread was started by this call.
        """
        # The state lock, not the basis' own: that one is held for the whole build.
        with self._state_lock:
            if not self.has_asymmetric or self._asym_prewarm is not None:
                return False

            def build() -> None:
                try:
                    self.asymmetric()
                except Exception:
                    log.exception("building the basis for specimens without twofold symmetry "
                                  "failed")

            self._asym_prewarm = threading.Thread(target=build, daemon=True,
                                                  name="gonio-asymmetric-basis")
        self._asym_prewarm.start()
        return True

    @property
    def asymmetric_prewarming(self) -> bool:
        """Whether :meth:`prewarm_asymmetric` has started a build in this process."""
        return self._asym_prewarm is not None

    def asymmetric_wait_report(self, waited_s: float) -> tuple[str, float | None]:
        """What a job waiting ``waited_s`` seconds for the asymmetric basis is told, in words,
        and the fraction done if known (not known: the build reports no progress)."""
        what = ("the specimen is not twofold symmetric: {} the reconstruction basis for such "
                "specimens")
        if waited_s < 1.0 or not self.asymmetric_build_needed():
            return (what.format("loading"), None)
        seconds = self.asymmetric_build_s() or 0.0
        return (what.format("building") + " (first such scan on this install, about "
                f"{max(1.0, seconds / 60):.0f} minutes; later scans reuse it)", None)

    def asymmetric_build_s(self) -> float | None:
        """Seconds a job whose specimen is found asymmetric waits at finishing for the
        asymmetric basis to be built (:data:`gonio.plans.dryrun.ASYMMETRIC_BASIS_BUILD_S`,
        plus :data:`gonio.plans.dryrun.BASIS_BUILD_S` when the default training library is
        not tabulated on this install either); None when no build is due."""
        if not self.asymmetric_build_needed():
            return None
        from gonio.brdf.materials.library import build_progress
        from gonio.plans.dryrun import ASYMMETRIC_BASIS_BUILD_S, BASIS_BUILD_S

        done, total = build_progress()
        return ASYMMETRIC_BASIS_BUILD_S + (BASIS_BUILD_S if done < total else 0.0)

    def asymmetric_build_needed(self) -> bool:
        """Whether the next :meth:`asymmetric` will *build* that basis (minutes): the default
        supply without its cache file. Known without a load; False for a supply that has none
        or a provider of its own (taken to load quickly)."""
        if not self.is_default or self._asymmetric_provider is not None:
            return False
        from gonio.brdf.reconstruction.basis import default_basis_path

        return not default_basis_path(asymmetric=True).is_file()

    def build_needed(self) -> bool:
        """Whether the next :meth:`get` will *build* the default basis (minutes), not load it.

        True when its cache file does not exist yet and the shipped synthetic basis cannot
        serve (it is stale: the code that builds it changed). With the shipped one, a first
        scan or a ``gonio library import`` costs a fold-in of seconds: a load. A supply with
        its own provider (a saved basis, tests) is taken to load quickly.
        """
        if not self.is_default:
            return False
        from gonio.brdf.reconstruction import shipped
        from gonio.brdf.reconstruction.basis import default_basis_path

        return not default_basis_path().is_file() and not shipped.is_current()

    def symmetry(self) -> BasisSymmetry | None:
        """What the basis a job would reconstruct with says about half a turn, when that is
        known without building or calling a provider that may block: the default basis' cache
        file (read once per version), else the basis this supply has given; None when neither
        is known (the job says it once it has the basis)."""
        if not self.is_default:
            with self._state_lock:
                return self._seen
        from gonio.brdf.reconstruction.basis import Basis, BasisError, default_basis_path

        version = _version(default_basis_path())
        if version is None:
            return None
        with self._state_lock:
            known = self._file_symmetry
            if known is not None and known[0] == version:
                return known[1]
        try:
            symmetry = BasisSymmetry.of(Basis.load(version[0]))
        except BasisError:
            return None  # the build or the job says why
        with self._state_lock:
            self._file_symmetry = (version, symmetry)
        return symmetry

    def prewarm(self) -> None:
        """Build the basis now in a thread of its own (at a daemon's start, for queued jobs
        that measure with it), unless one was started already; a job's own :meth:`get` waits
        for it. A failure is logged: the job's own load reports it, with the job."""
        if self._prewarm is not None:
            return

        def build() -> None:
            try:
                self.get()
            except Exception:
                log.exception("building the basis at start failed")

        # A daemon thread, not an executor's: shutting down must not wait for a build.
        self._prewarm = threading.Thread(target=build, name="gonio-basis-prewarm", daemon=True)
        self._prewarm.start()

    @property
    def prewarming(self) -> bool:
        """Whether :meth:`prewarm` has started a build in this process."""
        return self._prewarm is not None

    def wait_report(self, why: str, waited_s: float) -> tuple[str, float | None]:
        """What a job waiting ``waited_s`` seconds for the basis is told, in words, and the
        fraction done if known.

        While the default basis must be built (:meth:`build_needed`) and the wait lasts more
        than a moment, the report counts the library materials tabulated so far, then says
        the basis is being learned. ``why`` ends the phrase (e.g. " before the first reading").
        """
        if not self.is_default or waited_s < 1.0 or not self.build_needed():
            return ("loading the reconstruction basis" + why, None)
        from gonio.brdf.materials.library import build_progress

        done, total = build_progress()
        if done < total:
            return (f"building the BRDF training library{why}, {done} of {total} materials "
                    "(first scan on this install; later scans reuse it)",
                    done / total if total else None)
        return (f"learning the reconstruction basis from the library{why} (first scan on this "
                "install, about a minute; later scans reuse it)", None)

    # ------------------------------------------------------------------ the arc warning
    def note_arc(self, store: JobStore, job_id: int, plan: AnyPlan,
                 symmetry: BasisSymmetry | None) -> str | None:
        """Record the job's arc warning (:func:`gonio.plans.dryrun.arc_warning`) as its
        ``arc_warning`` event, once per job, and return it (None when there is none).

        Called when the job is queued, when it starts and when its finishing has the basis:
        whichever first knows the basis records it, so a job left to run unattended carries
        the warning in its own record (the joint fit still takes the scan: no refusal). A job
        resumed after a restart has it already: the store is asked once per process.
        """
        message = arc_warning(plan, symmetry)
        if message is None or symmetry is None:
            return None
        with self._state_lock:
            if job_id in self._arc_noted:
                return message
            self._arc_noted.add(job_id)
        if not store.has_event(job_id, "arc_warning"):
            store.append_event(job_id, "arc_warning", {
                "message": message, "span_deg": plan.first_span_deg(),
                "materials": list(symmetry.without_twofold_symmetry)})
        return message


def _version(path: Path) -> _FileVersion | None:
    """``path`` with its (mtime in ns, size), or None when it does not exist."""
    try:
        st = path.stat()
    except OSError:
        return None
    return (path, st.st_mtime_ns, st.st_size)
