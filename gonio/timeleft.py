"""How long a job has left in all: measuring, then (when due) the basis build, then finishing.

The engine's ``eta_s`` covers measuring only. After the last reading the job finishes: it gets
the reconstruction basis (a load of seconds, or a build of minutes when the shipped basis is
stale), reconstructs and fits the exports. The lab page shows the sum, so a job's time is not
read as done when measuring ends (issue 27). Finishing is estimated from what it took on this
store: the ``seconds`` the last completed scans recorded in their summaries
(:func:`gonio.finishing.finish_job` measures them); before any scan has finished, from the
lab page's default scan as measured in docs/library.md.
"""

from __future__ import annotations

import statistics
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from gonio.store import JobRow

FINISHING_FALLBACK_S = 7.5
"""Finishing time of the lab page's default scan on the simulated rig (3 channels), seconds:
7.1-7.4 s measured with ``bench/bench_first_scan.py`` (docs/library.md), the upper end rounded
up."""

FALLBACK_S_PER_CHANNEL = 0.1
"""Seconds the fallback adds for each sensor channel beyond three: the reconstruction, the
colour and the result file grow with the channels. The same scan on the simulated 31-band
spectrometers finished in 9.5-9.9 s against 6.2-7.1 s on the RGB rig (``bench/bench_first_scan.py
--runs 3 --keep-cache [--material metallic-blue-paint]``, docs/library.md): about 0.1 s a band."""

RECENT_SCANS = 3
"""How many of the last completed scans the estimate takes the median of: one slow finishing
(the first scan that built the basis) does not set the estimate of every later job."""


@dataclass(frozen=True)
class FinishingEstimate:
    """Estimated seconds of a job's finishing and, in words, what the estimate rests on."""

    seconds: float
    source: str


def finishing_estimate(completed: Sequence[JobRow], channels: int = 3) -> FinishingEstimate:
    """The finishing time to expect, from the completed jobs of the store (any order).

    Parameters
    ----------
    completed : the store's completed jobs; calibration jobs and summaries without a
        measured ``seconds`` are skipped (a calibration does not reconstruct).
    channels : the most channels of the rig's sensors (:func:`most_channels`): only scans
        whose stored rig had as many count (a 31-band scan finishes about 3 s later than an
        RGB one; one store can hold both when a lab swaps sensors), and with none, the
        fallback grows with them.

    Returns
    -------
    The median ``seconds`` of the newest :data:`RECENT_SCANS` completed scans with that many
    channels, or, when there is none, :data:`FINISHING_FALLBACK_S` plus
    :data:`FALLBACK_S_PER_CHANNEL` for each channel beyond three.
    """
    scans = [(row.id, float(row.summary["seconds"]), most_channels(row.rig))
             for row in completed
             if row.kind != "calibration" and row.summary
             and isinstance(row.summary.get("seconds"), int | float)
             and row.summary["seconds"] >= 0]
    alike = [(i, s) for i, s, c in scans if c == channels]
    timed = sorted(alike)[-RECENT_SCANS:]
    other = (f"; scans read with other than {channels} channels are not counted"
             if len(alike) < len(scans) else "")
    if not timed:
        extra = max(0, channels - 3)
        seconds = FINISHING_FALLBACK_S + FALLBACK_S_PER_CHANNEL * extra
        more = (f" and {FALLBACK_S_PER_CHANNEL:g} s for each of {extra} channels beyond three"
                if extra else "")
        which = f"scan with {channels} channels" if other else "scan"
        return FinishingEstimate(
            seconds,
            f"no {which} has finished on this job store yet: {seconds:g} s, the default "
            f"scan's measured finishing{more}")
    ids = ", ".join(str(i) for i, _ in timed)
    seconds = statistics.median(s for _, s in timed)
    what = f"job {ids}'s finishing" if len(timed) == 1 else f"the median of jobs {ids}"
    return FinishingEstimate(seconds, f"{what} on this job store{other}")


def most_channels(rig: Any) -> int:
    """The most channels any sensor of ``rig`` has (3 when none says).

    Parameters
    ----------
    rig : a :class:`gonio.rigdescription.RigDescription` or a rig config (``sensors``, each
        with ``channels``), or a job's stored rig (a dict of the same); what does not read
        so (a rig stored by older code) counts as no sensor.
    """
    if isinstance(rig, Mapping):
        sensors = rig.get("sensors")
        lists = [s.get("channels") for s in sensors if isinstance(s, Mapping)] \
            if isinstance(sensors, list) else []
    else:
        lists = [s.channels for s in getattr(rig, "sensors", None) or ()]
    return max((len(c) for c in lists if isinstance(c, list | tuple)), default=3)


def time_left(eta_s: float | None, basis_build_s: float | None, finishing_s: float,
              finishing_elapsed_s: float | None = None) -> float | None:
    """Estimated seconds to the job's end.

    Parameters
    ----------
    eta_s : measuring time left (the engine's ``eta_s``, counted down); None while the
        job measures but has no estimate yet (then the total is unknown too: None).
    basis_build_s : the basis build the job still waits for, seconds, or None.
    finishing_s : :func:`finishing_estimate`'s seconds.
    finishing_elapsed_s : while the job finishes, how long it has been finishing (measuring
        is over: ``eta_s`` is then ignored); None while it measures.

    Returns
    -------
    The seconds left, or None when unknown: no measuring estimate yet, or a finishing that
    has run past its estimate (it is not done, so 0 s would be false; how much longer it
    takes is not known).
    """
    if finishing_elapsed_s is not None:
        left = (basis_build_s or 0.0) + finishing_s - finishing_elapsed_s
        return left if left > 0.0 else None
    if eta_s is None:
        return None
    return eta_s + (basis_build_s or 0.0) + finishing_s


@dataclass(frozen=True)
class QueuedRun:
    """A queued job's estimated duration, start to end, for :func:`start_estimates`."""

    job_id: int
    seconds: float | None
    """Measuring (the dry run's), then finishing; None when it has no estimate."""
    bound: bool = False
    """True when ``seconds`` is an upper bound (an adaptive plan, every round in full)."""


@dataclass(frozen=True)
class StartEstimate:
    """When a queued job is estimated to start, and in words what that rests on (or why it
    is not known)."""

    seconds: float | None
    bound: bool
    source: str


def _jobs(ids: Sequence[int]) -> str:
    return f"job {ids[0]}" if len(ids) == 1 else "jobs " + ", ".join(str(i) for i in ids)


def start_estimates(rig_free_s: float | None, rig_free_bound: bool, rig_free_source: str,
                    queue: Sequence[QueuedRun]) -> list[StartEstimate]:
    """Estimated start of each queued job: the time until the rig is free plus the estimated
    durations of the queued jobs ahead of it.

    Parameters
    ----------
    rig_free_s : seconds until the job holding the rig has ended (0 when none does); None
        when that is not known (a job suspended or paused, a held queue, a job without an
        estimate yet): then no queued job's start is known.
    rig_free_bound : True when ``rig_free_s`` is an upper bound (an adaptive job, every round
        in full).
    rig_free_source : what ``rig_free_s`` rests on, in words, or why it is not known.
    queue : the queued jobs in the order the queue takes them.

    Returns
    -------
    One :class:`StartEstimate` per queued job, in ``queue``'s order. A job behind one without
    an estimate has none either (None, never a guess); its ``source`` names that job.
    """
    out: list[StartEstimate] = []
    t, bound = rig_free_s, rig_free_bound
    why = rig_free_source if rig_free_s is None else ""
    ahead: list[int] = []
    for run in queue:
        if t is None:
            out.append(StartEstimate(None, False, f"not known: {why}"))
        else:
            parts = [rig_free_source] if rig_free_s else []
            if ahead:
                parts.append(f"the estimated durations of {_jobs(ahead)} ahead")
            words = " plus ".join(parts) if parts else "nothing holds the rig or is ahead"
            if bound:
                words += ("; an upper bound: an adaptive job is counted with every refinement "
                          "round in full, and may stop sooner")
            out.append(StartEstimate(t, bound, words))
            if run.seconds is None:
                t, why = None, f"job {run.job_id} ahead of it has no duration estimate"
            else:
                t += run.seconds
                bound = bound or run.bound
        ahead.append(run.job_id)
    return out
