"""Finishing a measured job: from its stored readings to its result file.

The worker measures a job with the engine, then calls :func:`finish_job` in a thread. The
readings become calibrated samples (:func:`gonio.calibration.calibrated_samples`), and then,
by the plan's finishing kind:

* ``calibration`` (a white reference): per-pair factors
  (:func:`gonio.calibration.from_reference`), saved as the data directory's calibration in
  effect, and a result file with the samples;
* ``reconstruction`` (a specimen): the BRDF reconstructed against the basis
  (:func:`gonio.brdf.reconstruction.reconstruct.reconstruct`), the export fits, and a result
  file with the table, the error estimates and the fits.

Returns the job's summary (what the store keeps and the API shows as ``result``). Paths in it
are relative to the data directory (``results/job-<id>.h5``), so a data directory that is moved
or restored from a backup still finds its own files.

A specimen is calibrated with every pair of its plan or with none: a calibration that lacks some
of the plan's pairs fails the job (:meth:`gonio.calibration.Calibration.check_covers`) rather
than mixing sensor units and 1/sr in one result.
"""

from __future__ import annotations

import json
import logging
import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from gonio.basis_supply import BasisSupply
from gonio.brdf.mirrorgap import cells_gap_deg, gap_note
from gonio.calibration import (
    CALIBRATION_FILE,
    Calibration,
    calibrated_samples,
    from_reference,
    save_calibration,
    sensor_full_scale,
)
from gonio.plans.checked import CheckedPlan
from gonio.plans.dryrun import BasisSymmetry, arc_warning
from gonio.plans.models import AnyPlan, CalibrationPlan, PlanError
from gonio.plans.validation import plan_pairs
from gonio.rigdescription import RigDescription
from gonio.store import JobStore

if TYPE_CHECKING:  # the numerics load with the first reconstruction
    from gonio.brdf.reconstruction.basis import Basis

log = logging.getLogger("gonio.finishing")


@dataclass
class Finishing:
    """What finishing a job needs beyond the job itself.

    Attributes
    ----------
    store : JobStore
    desc : RigDescription of the rig the job ran on
    data_dir : results go to ``data_dir/results/job-<id>.h5``; calibrations to
        ``data_dir/calibration.json``
    basis : the process's reconstruction basis (:class:`gonio.basis_supply.BasisSupply`;
        may build it, slow)
    basis_at_hand : the basis the job measured with (loaded before an adaptive job's first
        reading), used instead of asking ``basis`` again
    calibration : returns the calibration to apply to a specimen's readings (asked only when
        one is finished: the latest calibration job may have replaced it meanwhile)
    provenance : extra provenance stored in every result (e.g. the rig config)
    fit_exports : store the factored and principled fits (exports then need no refit)
    true_material : simulated rigs: the recipe of the material on the stage, or None
    on_activity : told what finishing waits for ("basis", "reconstructing")
    stop : set (from any thread) to abort: finishing stops at its next step and writes
        nothing (:class:`FinishingStopped`)
    save_calibration : a calibration job's factors become the data directory's calibration
        in effect; False when a result is rebuilt (``gonio jobs rebuild``), which must not
        replace a later calibration
    note_arc : record the job's ``arc_warning`` event when it has one
        (:meth:`gonio.basis_supply.BasisSupply.note_arc`); False when a result is rebuilt
    keep_inputs : keep ``provenance`` and the true material in the store
        (:meth:`gonio.store.JobStore.set_finishing_inputs`), so ``gonio jobs rebuild`` writes
        what this finishing wrote (the design comparison and colour come from the rig config);
        False when a result is rebuilt from them
    """

    store: JobStore
    desc: RigDescription
    data_dir: Path
    basis: BasisSupply
    calibration: Callable[[], Calibration]
    provenance: dict[str, Any] = field(default_factory=dict)
    fit_exports: bool = True
    true_material: Callable[[], dict[str, Any] | None] | None = None
    on_activity: Callable[[str], None] = lambda what: None
    stop: threading.Event = field(default_factory=threading.Event)
    save_calibration: bool = True
    basis_at_hand: Basis | None = None
    note_arc: bool = True
    keep_inputs: bool = True

    def checkpoint(self, job_id: int, before: str) -> None:
        """Raise :class:`FinishingStopped` if an abort was asked for.

        Called between the steps (basis, reconstruction, fits) and right before anything is
        written, so an aborted job leaves no result file and no calibration behind.
        """
        if self.stop.is_set():
            raise FinishingStopped(f"job {job_id}: finishing aborted before {before}")


class FinishingStopped(Exception):
    """Finishing saw its :attr:`Finishing.stop` set and stopped without writing anything."""


def finish_job(job_id: int, plan: AnyPlan | CheckedPlan, how: Finishing) -> dict[str, Any]:
    """Turn job ``job_id``'s readings into its result file; returns the job's summary.

    Blocking (reconstruction and fits take seconds): the worker runs it in a thread. ``plan``
    is the job's plan as the worker checked it (its pairs are not derived again), or the
    stored plan as it is (a rebuild: its pairs are those of the rig it ran on).

    Raises
    ------
    gonio.calibration.CalibrationError
        Incomplete readings, a white reference that does not read like one, or a calibration
        without factors for some of the plan's pairs.
    PlanError
        The plan's sensors do not share one channel list.
    """
    from gonio.results import write_result

    t0 = time.perf_counter()
    desc = how.desc
    job = how.store.get_job(job_id)
    if isinstance(plan, CheckedPlan):
        pairs, plan = list(plan.pairs), plan.plan
    else:
        pairs = plan_pairs(plan, desc)
    light_dirs, sensor_dirs = desc.pair_directions(pairs)
    channel_sets = {desc.sensor(p.sensor).channels for p in pairs}
    if len(channel_sets) != 1:
        raise PlanError(
            f"the plan's sensors have different channels {sorted(channel_sets)}; measure "
            "pairs whose sensors share one channel list"
        )
    channels = next(iter(channel_sets))
    readings = how.store.readings(job_id)
    is_cal = plan.finishing == "calibration"
    cal = Calibration() if is_cal else how.calibration()
    cal.check_covers(pairs, f"job {job_id}")
    samples = calibrated_samples(readings, pairs, light_dirs, sensor_dirs, channels, cal)
    relative = result_relpath(job_id)
    path = how.data_dir / relative
    provenance: dict[str, Any] = {
        "plan": json.dumps(job.plan), "rig": json.dumps(job.rig),
        "calibration": cal.model_dump_json(), **how.provenance,
    }
    summary: dict[str, Any] = {
        "readings": len(readings), "angles": int(samples.stage_angles_deg.size),
        # Calibrated means every value of the result is in 1/sr (check_covers above); a
        # calibration job's samples are the reference's sensor units.
        "pairs": len(pairs), "calibrated": bool(cal.pairs),
        # What the values were calibrated with, so the result can be rebuilt from the stored
        # readings as it was made (gonio jobs rebuild), whatever is in effect by then.
        "calibration": cal.model_dump(mode="json"),
    }
    kept = how.store.finishing_inputs(job_id) or {}
    if "true_material" in kept:
        # A finishing resumed after a restart records the specimen its readings came from,
        # kept when it first began: a simulated rig started again on another material
        # (``gonio serve --sim --material``) holds that one now.
        truth = kept["true_material"]
    else:
        truth = how.true_material() if how.true_material is not None else None
    if how.keep_inputs:
        # Before anything is written: a rebuild (even of a job whose result write failed)
        # then has the rig config and truth this finishing used.
        how.store.set_finishing_inputs(job_id, {"provenance": how.provenance,
                                                "true_material": truth,
                                                "fit_exports": how.fit_exports,
                                                "calibration": cal.model_dump(mode="json")})
    warning = exposure_mismatch(cal, readings)
    if warning is not None:
        summary["calibration_warning"] = warning
        provenance["calibration_warning"] = warning
    if is_cal:
        assert isinstance(plan, CalibrationPlan)  # the one kind that finishes so
        how.checkpoint(job_id, "saving the calibration")
        new_cal = from_reference(
            plan.reference_albedo,
            {(p.light, p.sensor): samples.values[q] for q, p in enumerate(pairs)},
            exposure_s=plan.exposure.exposure_s,
            source=f"job {job_id}: {plan.reference_name}",
            # Dated by its readings, not by when finishing ran: a rebuild gives the same.
            created=max((r.t_read for r in readings), default=None),
        )
        provenance["new_calibration"] = new_cal.model_dump_json()
        # The result first, then the calibration (each written whole or not at all): a
        # result that cannot be written (a full disk, a kill) leaves the calibration in
        # effect as it was, never a new one whose job shows failed or unfinished.
        write_result(path, job_id=job_id, specimen=job.specimen, kind=job.kind,
                     readings=readings, samples=samples, provenance=provenance,
                     metrics={"seconds": time.perf_counter() - t0})
        if how.save_calibration:
            try:
                how.checkpoint(job_id, "saving the calibration")
                save_calibration(new_cal, how.data_dir / CALIBRATION_FILE,
                                 _full_scale(how.provenance))
            except BaseException:
                # The job fails (or stops) without its calibration: nor does it keep a
                # result that says it made one.
                path.unlink(missing_ok=True)
                raise
        summary.update(result_path=relative, calibration_path=CALIBRATION_FILE)
        return summary

    from gonio.brdf.reconstruction.reconstruct import reconstruct

    how.on_activity("basis")
    try:
        basis = how.basis_at_hand if how.basis_at_hand is not None else how.basis.get()
    finally:
        how.on_activity("reconstructing")
    # The twofold symmetry test first (an auto-arc scan's own, or one made here on the readings):
    # a specimen it calls asymmetric is reconstructed with a basis that can hold it.
    test = _arc_test(how.store, job_id, plan, samples.stage_angles_deg,
                     lambda: calibrated_samples(readings, pairs, light_dirs, sensor_dirs,
                                                channels, Calibration()).values)
    basis, switch = _basis_for_test(how, job_id, plan, basis, test)
    # A half-turn scan with a basis whose prior varies over a full turn: the result is valid
    # but the other half turn rests on the prior; the job's events (once: the worker's start
    # may have said it), its summary and its result say so (docs/science.md 7.4).
    symmetry = BasisSymmetry.of(basis)
    arc = (how.basis.note_arc(how.store, job_id, plan, symmetry) if how.note_arc
           else arc_warning(plan, symmetry))
    how.checkpoint(job_id, "reconstructing")
    grid = samples.to_samples()
    # The joint fit takes the scan's own anisotropy when it is less than the library prior's
    # (reconstruct's rho="scan", docs/science.md 7.3); settings["prior_rho"] says which.
    rec = reconstruct(basis, grid.cells, grid.ph_lab, grid.stage_angles,
                      np.maximum(grid.values, 0.0), channels=channels, name=job.specimen)
    colour = _colour(rec, how, [p.sensor for p in pairs], bool(cal.pairs), samples)
    metrics: dict[str, Any] = {
        "rel_sample_error": rec.rel_sample_error,
        "estimated_error": rec.estimated_error,
        # The reported error bar: calibrated leave-one-pair-out error (science notebook 4.1);
        # V&F's estimated_error stays for comparison with the paper.
        "predicted_error": _finite_or_none(rec.predicted_error),
        "cv_sample_error": _finite_or_none(rec.cv_sample_error),
        # The headline self-estimate: expected log_rmse (cosine-weighted log error, what a
        # rendering sees) against the true BRDF, calibrated on held-out materials
        # including measured ones (docs/science.md).
        "predicted_log_rmse": _finite_or_none(rec.predicted_log_rmse),
        "cv_log_error": _finite_or_none(rec.cv_log_error),
        "cv_log_under": _finite_or_none(getattr(rec, "cv_log_under", float("nan"))),
        # The coverage witness of predicted_log_rmse: the share of the prior's weighted
        # variance the layout leaves (joint fit only; docs/science.md 7.1.1).
        "uncovered_share": _finite_or_none(rec.uncovered_share),
        # The upper end of the self-estimate's interval (joint fit only; science.md 7.1.1).
        "predicted_log_rmse_upper": _finite_or_none(rec.predicted_log_rmse_upper),
        "n_pairs": len(pairs),
        "n_angles": int(samples.stage_angles_deg.size),
        "n_samples": len(pairs) * int(samples.stage_angles_deg.size),
        "K": int(basis.K),
        "seconds": time.perf_counter() - t0,
    }
    if "prior_rho" in rec.settings:
        metrics["prior_rho"] = rec.settings["prior_rho"]  # 1: the library prior as it is
    if rec.settings.get("local_prior") is not None:
        # The folded-in (measured or user) material whose shape the fit leaned on where no
        # pair looks; absent: the library's prior alone (docs/science.md 7.2.3).
        metrics["local_prior"] = str(rec.settings["local_prior"])
        provenance["local_prior"] = str(rec.settings["local_prior"])
        metrics["local_prior_gain"] = rec.settings["local_prior_gain"]
        own = own_result_prior(str(rec.settings["local_prior"]), job.specimen)
        if own is not None:
            metrics["local_prior_own"] = own
            provenance["local_prior_own"] = own
            log.info("job %d: %s", job_id, own)
    if rec.misfit is not None:
        # How far the fit misses its own readings against their noise; when the basis cannot
        # hold them, predicted_log_rmse was widened and the result says why (science.md 7.1.1).
        metrics.update(misfit_chi2=_finite_or_none(rec.misfit.chi2),
                       misfit_log=_finite_or_none(rec.misfit.log_misfit),
                       misfit_persistent_pairs=rec.misfit.persistent_pairs,
                       predicted_log_rmse_unwidened=_finite_or_none(
                           rec.predicted_log_rmse_unwidened))
    _record_adaptive_stop(how.store, job_id, metrics, provenance)
    misfit_message = rec.misfit_warning
    if misfit_message is not None and not cal.pairs:
        # The basis holds BRDFs in 1/sr; sensor units differ from them by each pair's own
        # factor (lamp, sensor, geometry), so an uncalibrated scan's readings miss it whatever
        # the material: the message's "unlike the training library" would send the lab the
        # wrong way.
        misfit_message += (". This scan is uncalibrated: its values are sensor units, which "
                           "differ from 1/sr by each pair's own factor, so the basis misses "
                           "them whatever the material; calibrate with the white reference "
                           "on the stage (gonio scan --white-reference 0.99) and scan again "
                           "before reading this as the material's")
    if misfit_message is not None:
        metrics["basis_misfit"] = misfit_message
        provenance["basis_misfit"] = misfit_message
        log.info("job %d: %s", job_id, misfit_message)
    # A reconstruction outside physical bounds (albedo far above 1, or orders of magnitude
    # above every reading) completes with a warning rather than failing: the readings and the
    # table where the pairs look are still the measurement, a rebuild with another basis can
    # use them, and a failed job would hide both (docs/science.md 7.6).
    physical = physical_bounds(rec.table, grid.values, grid.cells, bool(cal.pairs),
                               rec.peak_excess_log_rmse)
    metrics.update(worst_directional_albedo=physical.as_dict()["worst_albedo"],
                   peak_to_reading_ratio=physical.as_dict()["peak_ratio"],
                   # predicted_log_rmse is never below this (science.md 7.5)
                   peak_excess_log_rmse=physical.as_dict()["peak_excess_log_rmse"])
    bounds_message = physical.message()
    if bounds_message is not None:
        metrics["physical_bounds"] = bounds_message
        provenance["physical_bounds"] = bounds_message
        log.info("job %d: %s", job_id, bounds_message)  # the worker records the event
    # Where the table peaks far above every reading, its highlight (height, width, colour) is
    # the prior's extrapolation, not the specimen's: the result says so (science.md 7.1.1).
    # reconstruct() read it from the same table and readings for the self-estimate (on either
    # path, so it is never None here): reported as it is, not computed a second time.
    highlight = rec.highlight
    assert highlight is not None
    metrics.update(highlight.as_metrics())
    highlight_message = highlight.message()
    if highlight_message is not None:
        metrics["highlight_not_read"] = highlight_message
        provenance["highlight_not_read"] = highlight_message
        log.info("job %d: %s", job_id, highlight_message)
    # A layout whose pairs all stand off the mirror direction cannot read a highlight narrower
    # than that gap, and its self-estimate cannot see one either (gonio.brdf.mirrorgap): the
    # result states the gap, a fact of the layout, beside the estimate.
    gap = cells_gap_deg(grid.cells)
    metrics["mirror_gap_deg"] = gap
    if (gap_message := gap_note(gap)) is not None:
        metrics["mirror_gap"] = gap_message
        provenance["mirror_gap"] = gap_message
    _compare_with_design(rec, readings, plan, samples, len(pairs), bool(cal.pairs),
                         how.provenance, metrics, provenance)
    if "design_gap" in metrics:
        log.info("job %d: %s", job_id, metrics["design_gap"])  # the worker records the event
    provenance.update(basis_K=int(basis.K), basis_materials=json.dumps(list(basis.materials)))
    _record_arc_test(job_id, plan, test, metrics, provenance)
    if switch is not None:
        metrics.update(reconstruction_basis=switch.basis, **switch.entries())
        provenance.update(reconstruction_basis=switch.basis, **switch.entries())
    if arc is not None:
        summary["arc_warning"] = arc
        provenance["arc_warning"] = arc
    how.checkpoint(job_id, "the export fits")
    fit_table = colour.pop("fit_table")
    if "colour_space" in fit_table.provenance:
        # The export fits are linear sRGB from XYZ: every export says so (gonio.export.metadata
        # reads this entry instead of its "uncalibrated sensor RGB" statement).
        from gonio.result_colour import colour_statement

        provenance["colour_space"] = colour_statement(fit_table.provenance["colour_space"])
    fits = _fits(job_id, fit_table) if how.fit_exports else None
    if fits is not None:
        metrics.update(
            factored_rel_mse=fits.factored.metrics["rel_mse"],
            factored_psnr=fits.factored.metrics["psnr"],
            principled_roughness=fits.principled.roughness,
            principled_log_rmse=fits.principled.metrics["log_rmse"],
        )
    metrics["seconds"] = time.perf_counter() - t0
    if truth is not None:
        provenance["true_material"] = json.dumps(truth)
    how.checkpoint(job_id, "writing the result")
    write_result(
        path, job_id=job_id, specimen=job.specimen, kind=job.kind, readings=readings,
        samples=samples, table=rec.table, coefficients=rec.coefficients,
        rel_sample_error=rec.rel_sample_error, estimated_error=rec.estimated_error,
        settings=rec.settings, metrics=metrics, provenance=provenance,
        factored=fits.factored if fits else None,
        principled=fits.principled if fits else None, colour=colour,
    )
    summary.update(result_path=relative, **metrics)
    # The file's `seconds` cannot hold its own writing; the summary's does, since the status's
    # finishing estimate (gonio.timeleft) promises the result file too: a 31-band result's
    # write is over a second (bench/bench_first_scan.py --material metallic-blue-paint).
    summary["seconds"] = time.perf_counter() - t0
    return summary


def _compare_with_design(rec: Any, readings: list[Any], plan: AnyPlan, samples: Any,
                         n_pairs: int, calibrated: bool, extra: dict[str, Any],
                         metrics: dict[str, Any], provenance: dict[str, Any]) -> None:
    """The scan's ``predicted_log_rmse`` beside the expected error of the design its rig config
    came from (its ``[design]`` table, :mod:`gonio.designgap`): ``metrics`` gain
    ``design_expected_log_rmse`` and, for a gap above x2 either way, ``design_gap`` (why);
    ``provenance`` the design and the gap. Nothing without a ``[design]`` table, except a
    rebuild's :data:`DESIGN_COMPARISON` ("not available: ...") in ``extra``, which becomes a
    metric."""
    from gonio.designgap import compare_with_design, design_expectation, scan_facts

    design = design_expectation(extra.get("rig_config"))
    if design is None:
        if isinstance(extra.get(DESIGN_COMPARISON), str):
            # A rebuild that could not recover the rig config: say so where the comparison
            # would show (the provenance already holds it).
            metrics[DESIGN_COMPARISON] = extra[DESIGN_COMPARISON]
        return
    provenance["design"] = design.model_dump_json()
    if design.expected_log_rmse is None:  # a design recorded without its held-out error
        return
    metrics["design_expected_log_rmse"] = design.expected_log_rmse
    span = getattr(plan, "first_span_deg", None)
    facts = scan_facts(rec, readings, n_angles=int(samples.stage_angles_deg.size),
                       span_deg=float(span()) if callable(span) else 360.0,
                       n_pairs=n_pairs, calibrated=calibrated)
    gap = compare_with_design(facts, design)
    if gap is not None:
        metrics["design_gap"] = gap.message()
        provenance["design_gap"] = gap.message()


def _arc_test(store: JobStore, job_id: int, plan: AnyPlan, angles_deg: Any,
              counts: Callable[[], NDArray[np.float64]]) -> dict[str, Any] | None:
    """The scan's twofold symmetry test (docs/science.md 7.4), or None when it has none.

    An auto-arc plan's test is its ``arc_test`` event (what the scan chose, on its first
    round's readings). A plan of a fixed arc whose readings include opposite stage angles
    (8 uniform angles over a full turn hold 4 such pairs) is tested here, on the same
    ``raw - dark`` counts the auto-arc round tests (:func:`gonio.plans.arc.arc_test`, the same
    test and level): ``counts()`` gives them as ``(n_pairs, r, C)`` in the order of
    ``angles_deg`` (degrees). Not the calibrated values: a spectral calibration lifts a dim
    band to its neighbours' level without lowering its shot noise, and the test then took
    that noise for asymmetry.
    """
    from gonio.plans.arc import ARC_TEST_EVENT, arc_test

    if plan.arc_mode() == "auto":
        ev = store.last_event(job_id, ARC_TEST_EVENT)
        return None if ev is None else ev.data
    angles = np.asarray(angles_deg, float)
    gap = np.abs((angles[:, None] - angles[None, :]) % 360.0 - 180.0)
    if not (gap <= 0.5).any():  # no readings 180 deg apart: nothing to test
        return None
    return arc_test([float(x) for x in angles], counts(),
                    float(getattr(plan, "arc_noise", 0.01)))


@dataclass(frozen=True)
class BasisSwitch:
    """Which basis reconstructed a scan whose twofold symmetry test ran, and why.

    Attributes
    ----------
    basis : ``"asymmetric"`` (the supply's basis with odd harmonics,
        :meth:`gonio.basis_supply.BasisSupply.asymmetric`) or ``"default"``
    message : one sentence: the switch made (with the time its basis took, and whether it was
        built for this job), or why it was not made (None: a symmetric specimen, nothing to
        say)
    """

    basis: str
    message: str | None = None

    def entries(self) -> dict[str, Any]:
        """The summary's, metrics' and provenance's entries beside ``reconstruction_basis``:
        ``basis_switch`` (the message) when there is one."""
        return {} if self.message is None else {"basis_switch": self.message}


def _basis_for_test(how: Finishing, job_id: int, plan: AnyPlan, basis: Basis,
                    test: dict[str, Any] | None) -> tuple[Basis, BasisSwitch | None]:
    """The basis to reconstruct with, given the scan's symmetry test (docs/science.md 7.4).

    A specimen the test calls asymmetric over a full turn, with a basis whose prior along
    ``ph`` has only even harmonics (the shipped one), is reconstructed with the supply's basis
    with odd harmonics instead: the symmetric basis cannot represent what the other half turn
    read. Over half a turn (a forced half turn) the switch would not help: the readings
    cannot tell an odd harmonic from its alias, so the basis is kept (and the result warned,
    :func:`_record_arc_test`). None when the scan had no test.
    """
    if test is None:
        return basis, None
    asymmetric = test.get("statistic") is not None and not test.get("symmetric", True)
    # The arc the stage angles covered: an auto-arc plan's is the one its test chose.
    full_turn = (float(test.get("arc_deg", 180.0)) if plan.arc_mode() == "auto"
                 else plan.first_span_deg()) >= 360.0
    if not asymmetric:
        return basis, BasisSwitch("default")
    if not full_turn:
        return basis, BasisSwitch("default")  # arc_asymmetric says why (_record_arc_test)
    if not basis.half_turn_periodic:
        # The basis in use already holds odd harmonics (a lab's imported tables): kept.
        return basis, BasisSwitch("default", "the specimen is not twofold symmetric; the "
                                  "reconstruction basis already holds odd harmonics along the "
                                  "specimen's rotation, so it was kept")
    if not how.basis.has_asymmetric:
        return basis, BasisSwitch("default", "the specimen is not twofold symmetric, but this "
                                  "process reconstructs with a basis of its own and has none "
                                  "with odd harmonics: reconstructed with it as it is")
    how.checkpoint(job_id, "getting the basis for specimens without twofold symmetry")
    build = how.basis.asymmetric_build_needed()
    how.on_activity("asymmetric_basis")
    t0 = time.perf_counter()
    try:
        asym = how.basis.asymmetric()
    except Exception as exc:  # the measurement is kept: the default basis reconstructs it
        log.exception("job %d: the basis for specimens without twofold symmetry failed", job_id)
        why = f"{type(exc).__name__}: {exc}"
        return basis, BasisSwitch(
            "default", "the specimen is not twofold symmetric, but the basis for such "
            f"specimens could not be had ({why}); reconstructed with the default basis, which "
            "cannot represent it: rebuild the result (gonio jobs rebuild) once the cause is "
            "fixed")
    finally:
        how.on_activity("reconstructing")
    seconds = time.perf_counter() - t0
    if asym is None:  # has_asymmetric said otherwise; kept for the type checker
        return basis, BasisSwitch("default")
    # Started when the test gave its verdict (the worker's prewarm): built mostly while the
    # stage read the other half turn.
    early = how.store.last_event(job_id, "basis_prewarm")
    if early is not None and early.data.get("basis") == "asymmetric":
        made = ("built for this job while the stage read its other half turn, once per "
                "install" + (f"; finishing waited {seconds:.0f} s for the rest" if build
                             else ""))
    elif build:
        made = f"built for this job in {seconds:.0f} s, once per install"
    else:
        made = "loaded"
    return asym, BasisSwitch(
        "asymmetric", "the twofold symmetry test found the specimen NOT twofold symmetric, so "
        "it was reconstructed with the basis for such specimens (trained on the library's "
        "families without twofold symmetry too: its prior along the rotation holds odd "
        f"harmonics; K = {asym.K}, {made}) instead of the default one, which cannot represent "
        "it (docs/science.md 7.4)")


def _record_adaptive_stop(store: JobStore, job_id: int, metrics: dict[str, Any],
                          provenance: dict[str, Any]) -> None:
    """Why an adaptive scan stopped refining (its last ``adaptive_done`` event), in its result.

    ``metrics["adaptive_stop"]``: ``converged`` (the rule asked for no more angles),
    ``budget`` or ``max_rounds`` (a limit of the plan); at a limit ``adaptive_wanted``, how
    many more angles the rule still asked for, and when it asked for any ``adaptive_limit``,
    the sentence that says so (also in the provenance, so exports carry it). Nothing for a
    plan that is not adaptive.
    """
    ev = store.last_event(job_id, "adaptive_done")
    if ev is None:
        return
    metrics["adaptive_stop"] = str(ev.data.get("reason"))
    if "wanted" in ev.data:
        metrics["adaptive_wanted"] = int(ev.data["wanted"])
    if ev.data.get("message"):
        metrics["adaptive_limit"] = str(ev.data["message"])
        provenance["adaptive_limit"] = str(ev.data["message"])


def _record_arc_test(job_id: int, plan: AnyPlan, test: dict[str, Any] | None,
                     metrics: dict[str, Any], provenance: dict[str, Any]) -> None:
    """The twofold symmetry test of the scan (:func:`_arc_test`) in its result
    (docs/science.md 7.4).

    ``metrics`` gain ``arc_symmetric``, ``arc_deg`` (the arc scanned: the one the test chose,
    or a fixed plan's own), ``arc_mode`` (the plan's: ``auto`` or ``fixed``, so what is said
    of the arc does not claim the test chose a fixed plan's) and the test's
    ``arc_test_statistic``, ``arc_test_dof``, ``arc_test_p_value``; ``provenance["arc_test"]``
    the whole test (for a fixed plan with ``arc_deg`` the plan's, ``arc_chosen_by`` ``"plan"``
    and ``arc_the_test_would_choose``). A plan forced over half a turn that the test
    calls asymmetric gets ``metrics["arc_asymmetric"]`` (the worker records it as an event,
    the page's headline shows it).
    """
    from gonio.plans.arc import half_turn_warning

    if test is None:
        return
    if plan.arc_mode() == "fixed" and plan.first_span_deg() == 180.0:
        warning = half_turn_warning(test)
        if warning is not None:
            metrics["arc_asymmetric"] = warning
            provenance["arc_asymmetric"] = warning
            log.info("job %d: %s", job_id, warning)  # the worker records the event
    mode = plan.arc_mode()
    metrics.update(arc_symmetric=bool(test["symmetric"]), arc_deg=float(test["arc_deg"]),
                   arc_mode=mode, arc_test_statistic=test.get("statistic"),
                   arc_test_dof=test.get("dof"), arc_test_p_value=test.get("p_value"))
    if mode == "fixed":
        # Forced: the test chose nothing. Its own arc_deg (what it would have chosen) said
        # 180 in the file of a scan over a full turn.
        metrics["arc_deg"] = plan.first_span_deg()
        test = {**test, "arc_deg": plan.first_span_deg(), "arc_chosen_by": "plan",
                "arc_the_test_would_choose": float(test["arc_deg"])}
    provenance["arc_test"] = json.dumps(test)


def physical_bounds(table: Any, values: Any, cells: Any, calibrated: bool,
                    peak_excess: float | None = None) -> Any:
    """:func:`gonio.brdf.tables.bounds.bounds_check` of a reconstruction against the readings
    it was fitted to (``values``, one row per pair of ``cells``, calibrated when
    ``calibrated``); ``peak_excess``: the reconstruction's own ``peak_excess_log_rmse``, so it
    is not computed twice."""
    from gonio.brdf.tables.bounds import bounds_check

    return bounds_check(table, values, cells=cells, calibrated=calibrated,
                        peak_excess=peak_excess)


def _colour(rec: Any, how: Finishing, sensors: list[str], calibrated: bool,
            samples: Any = None) -> dict[str, Any]:
    """The result's ``/colour`` group (docs/colour.md); a spectral sensor's band centres go on
    the reconstructed table (``rec`` is changed in place: its table gains the wavelengths).
    Its ``fit_table`` entry (taken out before writing) is the table the export fits are made
    of: linear sRGB when the channels have colour (``result_colour.table_for_fits``).

    Colour is a by-product: anything wrong with it is stored as the group's ``error`` and the
    measurement is kept.
    """
    from gonio.brdf.colour.errors import ColourError
    from gonio.brdf.tables.table import BRDFTable
    from gonio.result_colour import (
        colour_group,
        colour_source,
        report_instruments,
        scan_readings,
        table_for_fits,
    )

    try:
        source = colour_source(how.provenance.get("rig_config"), sensors)
    except (ColourError, ValueError, KeyError, TypeError) as exc:
        return {"source": {}, "fit_table": rec.table,
                "error": f"the rig config's colour description is unusable: {exc}"}
    centres = source.get("bands", {}).get("centres_nm")
    if centres is not None and len(centres) == rec.table.n_channels:
        t = rec.table
        object.__setattr__(rec, "table", BRDFTable.trusted(
            np.asarray(t.values), t.channels, t.name, centres, t.provenance))
    scan = None if samples is None else scan_readings(samples)
    instruments = report_instruments(how.provenance.get("rig_config"))
    return {**colour_group(rec.table, source, calibrated, scan, instruments),
            "fit_table": table_for_fits(rec.table, source, calibrated)}


def result_relpath(job_id: int) -> str:
    """Where job ``job_id``'s result file lives, relative to the data directory (what the
    store records: docs/engine.md)."""
    return f"results/job-{job_id}.h5"


def _full_scale(provenance: dict[str, Any]) -> dict[str, Any]:
    """The sensors' full scales of the rig config recorded in ``provenance`` (empty without
    one), so a new calibration is checked as it will be when loaded."""
    text = provenance.get("rig_config")
    if not isinstance(text, str):
        return {}
    from gonio.config import RigConfig

    try:
        return sensor_full_scale(RigConfig.model_validate_json(text))
    except ValueError:
        return {}


def _fits(job_id: int, table: Any) -> Any:
    """The export fits (factored, principled) of a reconstruction, or None.

    They make the result file exportable without refitting; a fit that fails must not
    cost the user the measurement, so the failure is logged and the result kept.
    """
    from gonio.export import fit_all
    from gonio.export.child import run_fits

    try:
        # In a daemon, in a fresh interpreter: half the CPU (gonio.export.child).
        return run_fits(fit_all, table)
    except (ValueError, ArithmeticError, np.linalg.LinAlgError) as exc:
        log.warning("job %d: export fits failed (%s); the result is kept without them",
                    job_id, exc)
        return None


def exposure_mismatch(cal: Calibration, readings: list[Any]) -> str | None:
    """Why the calibration may not fit these readings, or None.

    Factors are not rescaled between exposure times (sensors need not be linear in exposure),
    so a scan at another exposure than its calibration is flagged rather than silently trusted.
    """
    used = sorted({float(r.exposure_s) for r in readings})
    if cal.exposure_s is None or not any(cal.measured_at_another_exposure(t) for t in used):
        return None
    return (f"the calibration was measured at exposure {cal.exposure_s:g} s, this scan at "
            f"{', '.join(f'{t:g}' for t in used)} s; its values are off by about the ratio. "
            "Calibrate at the scan's exposure")


def own_result_prior(name: str, specimen: str) -> str | None:
    """What a result must say when its joint fit leaned on the local prior of a user-library
    table that is this specimen's own earlier gonio result (exported with ``gonio export
    --format table``, then ``gonio library import``; docs/science.md 7.2.3): where no pair
    looks the reconstruction repeats that earlier scan rather than measuring, and its
    ``predicted_log_rmse`` is not independent of it. None for any other prior (a shipped
    measured material, another lab measurement, another specimen's result) or an unnamed
    specimen.

    Parameters
    ----------
    name : the local prior's material (the basis' ``local_names``; a user table's file stem)
    specimen : the job's specimen name
    """
    from gonio.brdf.materials.measured import user_table_provenance
    from gonio.export.metadata import specimen_name

    prov = user_table_provenance(name)
    if prov is None or prov.get("job_id") is None:
        return None  # not an export of a gonio result
    theirs, named = specimen_name(prov.get("specimen"))
    ours, ours_named = specimen_name(specimen)
    if not (named and ours_named) or theirs.strip().casefold() != ours.strip().casefold():
        return None
    source = prov.get("source")
    scan = f"{source} scan" if isinstance(source, str) and source else "scan"
    return (f"prior: the fit leaned on {name}, this specimen's own earlier result ({scan}, "
            f"job {prov['job_id']}) imported into the user library ({prov['file']}): where no "
            "pair looks this reconstruction repeats that one instead of measuring, and "
            "predicted_log_rmse is not independent of it; for an independent result move the "
            "file out of the library and rebuild this result (gonio jobs rebuild)")


def _finite_or_none(x: float) -> float | None:
    """NaN (e.g. no pair could be left out) is stored as null: JSON has no NaN."""
    return float(x) if math.isfinite(x) else None


_DISK_FULL = "disk full: "
"""How the reason of a job failed by a full disk begins
(:func:`gonio.diskspace.disk_full_message`)."""


class RebuildError(ValueError):
    """A result cannot be rebuilt from the job store; the message says why and what to do."""


def rebuild_result(store: JobStore, data_dir: Path, job_id: int,
                   basis: BasisSupply) -> dict[str, Any]:
    """Write job ``job_id``'s result file again from the readings the store holds
    (``gonio jobs rebuild``): finishing re-run on them, with the calibration the job was
    finished with (recorded in its summary), the rig snapshot and plan it ran with, and what
    its finishing took from the rig config (the design comparison, the colour) and, on a
    simulated rig, the true material (:meth:`gonio.store.JobStore.finishing_inputs`). A job
    finished by a gonio whose store did not keep them takes the rig config from its result
    file, or its result says why the design comparison is not available
    (:func:`_older_rig_config`). The job's summary is replaced by the new one; a calibration
    job's factors do not replace the calibration in effect.

    A job that failed while it was being finished (``failed`` straight from
    ``reconstructing``: the disk filled while its result was written, or reconstruction, fits,
    colour or the result writing raised, e.g. a bug fixed since or a basis file that did not
    read) with every angle of its plan measured holds every reading: it is finished here and
    becomes ``completed``, with the events its finishing would have recorded. So does one
    aborted while it was being finished (``aborted`` straight from ``reconstructing``: the
    lab stopped a finishing it thought stuck, then wants the result after all). A calibration
    job so completed puts its calibration in effect unless a later one is. If the finishing of
    a failed job fails again, the job stays ``failed`` with the new reason (a
    ``rebuild_failed`` event; its readings are untouched) and :class:`RebuildError` says why;
    an aborted one stays ``aborted`` as it was.

    Blocking (reconstruction and fits take seconds).

    Parameters
    ----------
    store : the job store holding the job and its readings
    data_dir : the data directory the result goes to (``results/job-<id>.h5``)
    job_id : a completed job, or one that failed or was aborted while finishing with every
        reading stored
    basis : the reconstruction basis (specimen jobs)

    Returns
    -------
    dict : the new summary

    Raises
    ------
    RebuildError
        The job is not completed (nor stopped while finishing with every reading stored), its
        plan or rig snapshot no longer parses, its readings are missing or incomplete, or the
        finishing of a failed job failed again (its new reason).
    """
    from gonio.jobstates import JobState
    from gonio.plans.models import parse_stored_plan

    job = store.get_job(job_id)
    completing = _stopped_while_finishing(store, job)
    if job.state is not JobState.COMPLETED and not completing:
        raise RebuildError(_not_rebuilt(store, job))
    try:
        plan = parse_stored_plan(job.plan)
        desc = RigDescription.model_validate(job.rig)
    except (PlanError, ValueError) as exc:
        raise RebuildError(f"cannot rebuild job {job_id}: its stored plan or rig snapshot no "
                           f"longer reads ({exc})") from None
    old = job.summary or {}
    n = store.reading_count(job_id)
    if n == 0:
        raise RebuildError(f"cannot rebuild job {job_id}: the job store holds none of its "
                           "readings; restore the store from a backup, or measure it again")
    if isinstance(old.get("readings"), int) and n < old["readings"]:
        raise RebuildError(f"cannot rebuild job {job_id}: the job store holds {n} of the "
                           f"{old['readings']} readings it was finished with; restore the "
                           "store from a backup, or measure it again")
    inputs = store.finishing_inputs(job_id) or {}
    stored = inputs.get("provenance")
    kept: dict[str, Any] = stored if isinstance(stored, dict) else {}
    if "provenance" not in inputs:
        # Finished by a gonio whose store did not keep its finishing inputs: the rig config
        # (the design comparison, the colour) is the one its result file recorded, if any.
        kept = _older_rig_config(Path(data_dir), job)
        if plan.finishing == "calibration":
            kept.pop(DESIGN_COMPARISON, None)  # a calibration is compared with no design
    cal: Calibration | None = None
    if isinstance(old.get("calibration"), dict):
        cal = Calibration.model_validate(old["calibration"])
    elif isinstance(inputs.get("calibration"), dict):
        # Failed before its summary was stored: finishing kept the calibration it applied.
        cal = Calibration.model_validate(inputs["calibration"])
    elif old.get("calibrated"):
        raise RebuildError(f"cannot rebuild job {job_id}: it was calibrated, and this store "
                           "(from an older gonio) does not record with which factors; measure "
                           "it again")
    elif completing and "calibration" not in inputs and plan.finishing != "calibration":
        # It failed before its finishing recorded the calibration it applies (a calibration
        # that did not read, a rig changed under a resumed job, an older gonio): finished
        # with none, a calibrated scan would come back "completed" in sensor units.
        raise RebuildError(
            f"cannot rebuild job {job_id}: it failed before its finishing recorded which "
            f"calibration its readings take ({job.reason or 'no reason recorded'}), so the "
            "rebuild cannot tell; its readings stay in the job store: measure it again "
            "(submit the same plan as a new scan)")
    applied = cal if cal is not None else Calibration()
    truth = inputs.get("true_material")
    how = Finishing(
        store=store, desc=desc, data_dir=Path(data_dir), basis=basis,
        calibration=lambda: applied, note_arc=False, keep_inputs=False,
        # A completed job's calibration stays as the calibration in effect is; a failed
        # calibration job's becomes it unless a later one is in effect.
        save_calibration=completing and _no_later_calibration(store, data_dir, job),
        provenance={**kept, "rebuilt": "from the job store's readings (gonio jobs rebuild) on "
                    + time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())},
        true_material=(lambda: truth) if isinstance(truth, dict) else None,
        # A store that kept no inputs: the fits were stored when its summary has their metric.
        fit_exports=bool(inputs.get("fit_exports", "factored_rel_mse" in old if old else True)),
    )
    from gonio.calibration import CalibrationError

    try:
        summary = finish_job(job_id, plan, how)
    except CalibrationError as exc:
        if completing:
            _failed_again(store, job, f"calibration refused (gonio jobs rebuild): {exc}")
        raise RebuildError(f"cannot rebuild job {job_id}: {exc}; "
                           + (f"it stays {job.state.value}{_WITH_REASON[job.state.value]}; "
                              if completing else "")
                           + "restore the store from a backup, or measure it again") from None
    except Exception as exc:
        if not completing:
            raise  # a completed job stays as it was: the error is the command's
        # Failed again (the cause is not fixed yet): the job keeps failing, with the new
        # reason the API and the page show; its readings are untouched.
        again = "failed again" if job.state is JobState.FAILED else "failed"
        reason = f"reconstruction {again} (gonio jobs rebuild): {exc}"
        _failed_again(store, job, reason)
        raise RebuildError(
            f"cannot rebuild job {job_id}: its finishing {again} ({reason}); it stays "
            f"{job.state.value}{_WITH_REASON[job.state.value]}, its {n} readings untouched: "
            f"remove the cause (e.g. a basis or library file that does not read, or update "
            f"gonio) and run gonio jobs rebuild {job_id} again") from exc
    if completing and store.get_job(job_id).state is not job.state:
        # Another rebuild finished it meanwhile (the store's lock keeps a daemon out, not a
        # second rebuild of a store nobody runs): its result stands.
        raise RebuildError(f"job {job_id} was rebuilt by another command meanwhile; it is "
                           f"{store.get_job(job_id).state.value} now")
    store.set_result(job_id, summary.get("result_path"), summary)
    store.append_event(job_id, "rebuilt", {"result_path": summary.get("result_path")})
    if completing:
        # What the worker records after a finishing, then the state the result now backs.
        for key in ("physical_bounds", "arc_asymmetric", "design_gap"):
            if summary.get(key):
                store.append_event(job_id, key, {"message": summary[key]})
        had = "failed" if job.state is JobState.FAILED else "been aborted while finishing"
        store.set_state(job_id, JobState.COMPLETED,
                        reason="completed by gonio jobs rebuild from its stored readings "
                        f"(it had {had}: {job.reason})")
    return summary


#: Provenance key (and metric) of a result whose design comparison could not be made: why.
DESIGN_COMPARISON = "design_comparison"


def _older_rig_config(data_dir: Path, job: Any) -> dict[str, Any]:
    """What a rebuild takes from the rig config of a job finished by a gonio whose job store
    kept no finishing inputs (:meth:`gonio.store.JobStore.finishing_inputs` is None).

    That gonio wrote the rig config into the result file's provenance (``rig_config``), so it
    is taken from there while the file still reads (``rig_config_from`` says so). Otherwise
    the design comparison cannot be made, and :data:`DESIGN_COMPARISON` says why ("not
    available: ..."); a result already rebuilt so keeps that reason.
    """
    from gonio.results import ResultFileError, read_provenance

    relative = job.result_path or result_relpath(job.id)
    try:
        old = read_provenance(data_dir / relative)
    except ResultFileError as exc:
        why = (f"its result file {relative} is missing" if not (data_dir / relative).is_file()
               else f"its result file does not read ({exc})")
    else:
        text = old.get("rig_config")
        if isinstance(text, str) and text:
            return {"rig_config": text,
                    "rig_config_from": f"{relative} as it was before this rebuild (finished "
                    "by a gonio whose job store did not keep the rig config)"}
        if isinstance(old.get(DESIGN_COMPARISON), str):
            return {DESIGN_COMPARISON: old[DESIGN_COMPARISON]}
        why = f"its result file {relative} records no rig config"
    return {DESIGN_COMPARISON: f"not available: job {job.id} was finished by a gonio whose "
            f"job store did not keep the rig config it ran on, and {why}, so the design it "
            "would be compared with is unknown"}


def completes_unfinished(store: JobStore, job_id: int) -> bool:
    """Whether :func:`rebuild_result` would finish job ``job_id`` and make it ``completed``
    (it failed or was aborted while finishing with every reading stored), changing its state;
    ``gonio jobs rebuild`` then holds the store's lock."""
    return _stopped_while_finishing(store, store.get_job(job_id))


#: How a rebuild that fails leaves a job it would have completed: a failed one takes the new
#: reason (``rebuild_failed``), an aborted one keeps its own (the lab's abort stands).
_WITH_REASON = {"failed": " with that reason", "aborted": " with its reason"}


def rebuild_command(job_id: int, store_path: str | Path,
                    data_dir: str | Path | None = None) -> str:
    """The ``gonio jobs rebuild`` command for job ``job_id`` of the store ``store_path`` (its
    SQLite file), ready to paste: absolute, quoted paths (a macOS data folder has a space in
    it), and ``--data-dir`` when the results go elsewhere than the store's own folder (a
    ``gonio scan --db`` elsewhere), which the command would otherwise take."""
    import shlex

    db = Path(store_path).resolve()
    cmd = f"gonio jobs rebuild {job_id} --db {shlex.quote(str(db))}"
    if data_dir is not None and Path(data_dir).resolve() != db.parent:
        cmd += f" --data-dir {shlex.quote(str(Path(data_dir).resolve()))}"
    return cmd


def rebuild_hint(store: JobStore, job_id: int, data_dir: str | Path | None = None
                 ) -> str | None:
    """What a job stopped while it was being finished (failed or aborted there) says about
    its readings: all are stored, and the command that finishes it (:func:`rebuild_result`);
    None when that rebuild would be refused because its finishing had not yet recorded the
    calibration its readings take (:func:`rebuild_result`'s own condition), or the store is in
    memory (nothing outlives the process)."""
    if store.path == ":memory:" or not _calibration_recorded(store, job_id):
        return None
    return (f"every reading is stored: '{rebuild_command(job_id, store.path, data_dir)}' "
            "finishes it once the daemon or scan running this store has stopped")


def _calibration_recorded(store: JobStore, job_id: int) -> bool:
    """Whether a rebuild of job ``job_id`` knows the calibration its readings take: a
    calibration job needs none, a completed job's summary records it, and a job stopped in
    its finishing has it once the finishing kept its inputs."""
    job = store.get_job(job_id)
    if _plan_kind(job.plan) == "calibration":
        return True
    if isinstance((job.summary or {}).get("calibration"), dict):
        return True
    return "calibration" in (store.finishing_inputs(job_id) or {})


def _stopped_while_finishing(store: JobStore, job: Any) -> bool:
    """Whether ``job`` failed or was aborted while it was being finished with every reading
    of its plan stored: ``failed`` or ``aborted`` straight from ``reconstructing`` (a full
    disk, an exception in reconstruction, fits, colour or the result writing, or an abort),
    every planned angle measured. A rebuild that failed again records no state change
    (``rebuild_failed``), so it still is."""
    from gonio.jobstates import JobState

    if job.state not in (JobState.FAILED, JobState.ABORTED) or not _all_measured(job):
        return False
    ev = store.last_event(job.id, "state")
    return ev is not None and ev.data.get("from") == JobState.RECONSTRUCTING.value


def _all_measured(job: Any) -> bool:
    """Every stage angle the job's plan laid out (all its rounds: the store's ``steps``,
    counted in ``total_angles``) has its readings committed."""
    return bool(job.total_angles) and job.done_angles >= job.total_angles


def _failed_again(store: JobStore, job: Any, reason: str) -> None:
    """Record that the rebuild of ``job`` (failed while finishing) failed again: the new
    reason replaces the old one, with a ``rebuild_failed`` event (no state change: the job
    was and stays ``failed``, and a later rebuild may still complete it). An aborted job is
    left as it was: its reason is the lab's abort, and the command says why it failed."""
    from gonio.jobstates import JobState

    if job.state is JobState.FAILED:
        store.set_failure_reason(job.id, reason, {"previous": job.reason})


def _not_rebuilt(store: JobStore, job: Any) -> str:
    """Why ``job`` (not completed) has no result to rebuild, and what to do."""
    from gonio.jobstates import JobState

    if job.state in (JobState.FAILED, JobState.ABORTED):
        failed = job.state is JobState.FAILED
        full = failed and (job.reason or "").startswith(_DISK_FULL)
        ev = store.last_event(job.id, "state")
        finishing = ev is not None and ev.data.get("from") == JobState.RECONSTRUCTING.value
        if ev is not None and ev.data.get("from") == JobState.QUEUED.value:
            why = job.reason or "no reason recorded"
            return (f"job {job.id} {'failed' if failed else 'was aborted'} before it started "
                    f"({why}): nothing was measured, so there is no result to write; submit "
                    "the plan again" + (" once the cause is fixed" if failed else ""))
        when = ("while it was being finished, its plan not wholly measured" if finishing
                else "while it was measuring, when the disk filled" if full
                else "while it was measuring")
        return (f"job {job.id} {'failed' if failed else 'was aborted'} {when} "
                f"({job.done_angles} of {job.total_angles} angles of its plan measured, "
                f"{store.reading_count(job.id)} readings stored; reason: "
                f"{job.reason or 'none recorded'}): its readings stay in the job store but are "
                "not a whole scan, so there is no result to write; measure it again (submit "
                "the same plan as a new scan)" + (" once the disk has room" if full else ""))
    return (f"job {job.id} is {job.state.value}: only a completed job's result is rebuilt, or "
            "that of one that failed or was aborted while it was being finished with every "
            "reading stored (a job still to finish writes its own)")


def _no_later_calibration(store: JobStore, data_dir: Path, job: Any) -> bool:
    """No calibration job completed after ``job`` was created (a later one's calibration is
    the one in effect and stays so)."""
    from gonio.jobstates import JobState

    return not any(r.id > job.id and r.state is JobState.COMPLETED
                   and _plan_kind(r.plan) == "calibration" for r in store.list_jobs())


def _plan_kind(plan: dict[str, Any]) -> str | None:
    """A stored plan's ``kind``, without parsing the rest."""
    kind = plan.get("kind")
    return kind if isinstance(kind, str) else None
