"""Which calibration each queued scan starts under, and whether its exposure matches.

Counts are not rescaled between exposure times, so the worker refuses a scan whose exposure is
not the one the calibration in effect at its start was measured at
(:meth:`gonio.calibration.Calibration.check_exposure`). Which calibration that is follows from
the queue: the last calibration job to run before the scan, else one under way, else the
calibration in effect now. This module walks a queue order and says, for each scan, whether it
would be refused; the service gives it the order, the exposures and the starting calibration
(:meth:`gonio.service.GonioService.start_refusals`, :meth:`~gonio.service.GonioService.reorder`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass


@dataclass(frozen=True)
class StartCalibration:
    """The calibration a queued job starts under when no queued calibration job runs before it.

    Attributes
    ----------
    exposure_s : exposure it was measured at, seconds; None when not recorded or no factors
        (nothing is refused then: the worker judges at the start)
    job_id : the calibration job under way that will be in effect, or None for the
        calibration in effect now
    """

    exposure_s: float | None
    job_id: int | None = None


@dataclass(frozen=True)
class ExposureClash:
    """A queued scan that would start under a calibration at another exposure.

    Attributes
    ----------
    job_id : the scan
    exposure_s : the scan's exposure, seconds
    under_s : the exposure of the calibration it would start under, seconds
    calibration_job : the calibration job that would be in effect (queued before the scan or
        under way), or None for the calibration in effect now
    """

    job_id: int
    exposure_s: float
    under_s: float
    calibration_job: int | None

    def under(self) -> str:
        """The calibration the scan would start under, in words."""
        if self.calibration_job is None:
            return f"the calibration in effect was measured at {self.under_s:g} s"
        return (f"calibration job {self.calibration_job}, the last to run before it, measures "
                f"at {self.under_s:g} s")

    def status(self) -> str:
        """What a queued scan's row says (the job list's ``start_refusal``)."""
        return (f"would be refused when it starts, as the queue stands: it reads at exposure "
                f"{self.exposure_s:g} s "
                f"and {self.under()} (counts are not rescaled between exposures). Cancel it "
                f"and queue it again at {self.under_s:g} s, or queue a calibration at "
                f"{self.exposure_s:g} s before it")


def exposure_clashes(order: Sequence[tuple[int, str]],
                     exposures: Mapping[int, float | None],
                     start: StartCalibration) -> dict[int, ExposureClash]:
    """The scans of a queue order that would start under a calibration at another exposure.

    Parameters
    ----------
    order : the queued jobs as ``(id, kind)`` in the order they will start
    exposures : each job's plan exposure by id, seconds (None or missing: not recorded; such
        a scan is not judged, such a calibration job makes the scans behind it unjudged)
    start : the calibration in effect before the first queued job

    Returns
    -------
    The clashing scans by id. Equal within a relative 1e-6, as the calibration's own check.
    """
    at, by = start.exposure_s, start.job_id
    out: dict[int, ExposureClash] = {}
    for job_id, kind in order:
        exposure = exposures.get(job_id)
        if kind == "calibration":
            at, by = exposure, job_id
        elif exposure is not None and at is not None and \
                not math.isclose(exposure, at, rel_tol=1e-6):
            out[job_id] = ExposureClash(job_id, exposure, at, by)
    return out
