"""gonio.queue_exposure: which calibration each queued scan starts under, judged against
queues written by hand (the expected clashes read off each order)."""

from __future__ import annotations

from gonio.queue_exposure import ExposureClash, StartCalibration, exposure_clashes


def test_each_scan_is_judged_by_the_last_calibration_before_it() -> None:
    # In effect 0.01 s; scan 1 at 0.01 (fine), calibration 2 at 0.02, scan 3 at 0.01
    # (clashes with job 2), calibration 4 at 0.01, scan 5 at 0.01 (fine), scan 6 at 0.5.
    order = [(1, "uniform"), (2, "calibration"), (3, "uniform"), (4, "calibration"),
             (5, "adaptive"), (6, "uniform")]
    exposures = {1: 0.01, 2: 0.02, 3: 0.01, 4: 0.01, 5: 0.01, 6: 0.5}
    got = exposure_clashes(order, exposures, StartCalibration(0.01))
    assert got == {3: ExposureClash(3, 0.01, 0.02, 2), 6: ExposureClash(6, 0.5, 0.01, 4)}


def test_the_start_calibration_judges_the_scans_ahead_of_every_queued_calibration() -> None:
    order = [(7, "uniform"), (8, "calibration"), (9, "uniform")]
    exposures = {7: 0.02, 8: 0.02, 9: 0.02}
    # The calibration in effect (no job) at 0.01 s: only the scan ahead of job 8 clashes.
    assert exposure_clashes(order, exposures, StartCalibration(0.01)) == {
        7: ExposureClash(7, 0.02, 0.01, None)}
    # A calibration job under way at 0.02 s: nothing clashes.
    assert exposure_clashes(order, exposures, StartCalibration(0.02, 3)) == {}


def test_what_is_not_recorded_is_not_judged() -> None:
    """No recorded exposure (an older calibration, a plan without one) is left to the worker,
    as Calibration.check_exposure accepts every exposure then; equal within 1e-6 relative."""
    order = [(1, "uniform"), (2, "calibration"), (3, "uniform")]
    assert exposure_clashes(order, {1: 0.02, 2: None, 3: 0.02}, StartCalibration(None)) == {}
    assert exposure_clashes(order, {1: 0.01 * (1 + 1e-9), 3: 0.5},
                            StartCalibration(0.01)) == {}  # job 2 has no exposure: 3 unjudged


def test_the_words_name_both_exposures_and_what_to_do() -> None:
    queued = ExposureClash(3, 0.01, 0.02, 2).status()
    assert queued.startswith("would be refused when it starts, as the queue stands: it reads "
                             "at exposure 0.01 s and "
                             "calibration job 2, the last to run before it, measures at 0.02 s")
    assert "queue it again at 0.02 s, or queue a calibration at 0.01 s before it" in queued
    assert "the calibration in effect was measured at 0.01 s" in \
        ExposureClash(7, 0.02, 0.01, None).status()
