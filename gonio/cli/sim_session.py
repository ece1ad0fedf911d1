"""A simulated rig driven through :class:`gonio.service.GonioService` (``gonio serve --sim``,
``gonio scan --sim``).

Two things a person at a real rig does, done here for the simulated one, once for both commands:

* the hand on the stage (:func:`attach_sim`): before a job measures, a calibration job gets the
  white reference and every other job the rig's specimen; results record the true material;
* the white-reference calibration (:func:`start_sim_calibration`): a calibration job queued
  first, the specimen put back the moment it stops measuring, so later scans are in 1/sr.
  The daemon queues it and goes on serving; ``gonio scan`` runs it in the foreground
  (:func:`calibrate_in_foreground`).
"""

from __future__ import annotations

import os
import re
import secrets
from pathlib import Path
from typing import Any

MEASURING_OVER = ("reconstructing", "completed", "failed", "aborted", "halted")
"""Job states after which the stage is free (the specimen may go back)."""
FINAL = ("completed", "failed", "aborted", "halted")


def sim_calibration_plan(albedo: float | None = None, exposure_s: float | None = None) -> Any:
    """The calibration plan of a simulated rig's white reference (default albedo
    :data:`gonio.sim.rig.WHITE_REFERENCE_ALBEDO`), at ``exposure_s`` (default: the plans'
    default exposure; a calibration serves scans at its own exposure only)."""
    from gonio.plans.models import CalibrationPlan, ExposureSettings
    from gonio.sim.rig import WHITE_REFERENCE_ALBEDO

    albedo = WHITE_REFERENCE_ALBEDO if albedo is None else albedo
    # The job list shows ``specimen``: name the reference there too, not "specimen".
    exposure = ExposureSettings() if exposure_s is None else ExposureSettings(
        exposure_s=exposure_s)
    return CalibrationPlan(reference_albedo=albedo, specimen="white reference",
                           reference_name=f"simulated white reference, albedo {albedo:g}",
                           exposure=exposure)


def attach_sim(service: Any, sim: Any) -> None:
    """Make the simulated stage hold what each job needs, as a person at the rig would, and
    record the material on the stage with each reconstruction (renderings show the truth).

    Before a job measures (started or resumed after a restart), a calibration job gets the
    white reference of its plan's albedo and every other job the rig's specimen.
    """
    from gonio.figures import describe_material

    follow_jobs_with_holder(service, sim)
    service.specimen_truth = lambda: describe_material(sim.specimen.brdf)


def follow_jobs_with_holder(service: Any, sim: Any) -> None:
    """The holder part of :func:`attach_sim` alone."""
    def prepare(job: Any) -> None:
        if job.kind == "calibration":
            sim.place_white_reference(float(job.plan.get("reference_albedo")))
        else:
            sim.load("specimen")

    service.on_job_start = prepare


def calibration_covers_rig(service: Any) -> bool:
    """Whether the calibration in effect has factors for every pair of the rig, one per channel
    of the pair's sensor.

    A simulated rig keeps its data directory (and calibration) across materials: a spectral
    material's 31-band sensors have the names and directions of an RGB material's, and a scan
    with the RGB calibration ran to its end and failed there ("calibration of pair L1/S1 has 3
    channels, the readings have 31").
    """
    return covers_rig(service.calibration(), service.desc.pairs, service.rig_config)


def sim_calibration_needed(cal: Any, pairs: Any, rig_config: Any, exposure_s: float) -> bool:
    """Whether ``gonio scan --sim`` calibrates the simulated rig before a scan at
    ``exposure_s``: calibration ``cal`` does not cover every pair (:func:`covers_rig`) or was
    measured at another exposure (a calibration serves its own exposure only). The scan and
    its dry run both ask it."""
    from gonio.calibration import exposure_warning

    return not covers_rig(cal, pairs, rig_config) or bool(exposure_warning(cal, exposure_s))


def covers_rig(cal: Any, pairs: Any, rig_config: Any) -> bool:
    """Whether calibration ``cal`` has factors for every one of ``pairs``, one per channel of
    the pair's sensor in ``rig_config`` (:func:`calibration_covers_rig` of a service; a dry
    run asks it of the calibration it reads from the data directory)."""
    if not cal.pairs or not cal.covers(pairs):
        return False
    sensors = getattr(rig_config, "sensors", None) or ()
    channels = {s.name: len(s.channels) for s in sensors}
    return all(len(p.factor) == channels.get(p.sensor, len(p.factor)) for p in cal.pairs)


def calibration_not_needed(service: Any) -> str | None:
    """Why no start-up calibration is queued (one is in effect, or one is pending), or None."""
    pending = [j for j in service.store.list_jobs()
               if j.kind == "calibration" and j.state.value in (
                   "queued", "running", "paused", "suspended", "reconstructing")]
    if pending:
        return (f"job {pending[0].id} (a calibration, {pending[0].state.value}) is still to "
                "finish; it runs on the white reference")
    if calibration_covers_rig(service):
        return f"in effect ({service.calibration().source}); scans are in 1/sr"
    return None


def start_sim_calibration(
    service: Any, sim: Any, albedo: float | None = None, report: Any = None,
    exposure_s: float | None = None,
) -> int:
    """Queue a white-reference calibration of a simulated rig, first in line; returns its job id.

    Call on the service's event loop. The white reference goes on the stage when the job starts
    measuring (:func:`follow_jobs_with_holder`, installed here if it is not yet), so a job
    resumed ahead of it still measures its own specimen; the specimen goes back from a store
    listener the moment the calibration leaves ``running``. When the job completes its factors
    are the calibration of every later scan.

    Parameters
    ----------
    service : gonio.service.GonioService
    sim : gonio.sim.rig.SimRig serving the rig the service drives
    albedo : float, optional
        Of the simulated reference (default :data:`gonio.sim.rig.WHITE_REFERENCE_ALBEDO`).
    report : callable, optional
        ``report(job_id, state, reason)`` when the job ends (completed, failed, ...).
    exposure_s : float, optional
        Of the calibration (default: the plans' default, 0.01 s).
    """
    from gonio.service import Event, JobRequest

    if service.on_job_start is None:
        follow_jobs_with_holder(service, sim)
    job: dict[str, Any] = {"id": None, "restored": False}

    def watch(ev: Event) -> None:
        if ev.job_id != job["id"] or ev.type != "state":
            return
        state = ev.data.get("state")
        if state in MEASURING_OVER and not job["restored"]:
            sim.load("specimen")
            job["restored"] = True
        if state in FINAL:
            service.remove_event_listener(handle)
            if report is not None:
                report(job["id"], state, ev.data.get("reason"))

    handle = service.add_event_listener(watch)
    try:
        plan = sim_calibration_plan(albedo, exposure_s)
        job["id"] = service.submit(JobRequest(plan=plan, priority=1000)).id
    except BaseException:
        service.remove_event_listener(handle)
        raise
    return int(job["id"])


async def calibrate_in_foreground(service: Any, sim: Any,
                                  exposure_s: float | None = None) -> str | None:
    """Run the white-reference calibration of :func:`start_sim_calibration` here and now
    (``gonio scan --sim``); returns None when it completed, else why not.

    Parameters
    ----------
    service : gonio.service.GonioService, not started (no queue worker)
    sim : gonio.sim.rig.SimRig
    exposure_s : float, optional
        The scan's exposure, which the calibration is measured at (counts are not rescaled
        between exposures).
    """
    import asyncio
    import sys

    from gonio.jobstates import JobState

    job_id = start_sim_calibration(service, sim, exposure_s=exposure_s)
    print(f"calibrating the simulated rig on a white reference (job {job_id})", file=sys.stderr)
    try:
        final = await service.run_in_foreground(job_id)
    except asyncio.CancelledError:
        # Ctrl-C (or SIGTERM, SIGHUP): the engine has stopped measuring. Left "running", the
        # job would be taken up by the next daemon on this data directory with whatever is
        # then on the stage, and listed as interrupted for ever; the same command calibrates
        # anew.
        row = service.store.get_job(job_id)
        if row.state.value not in FINAL:
            service.store.set_state(job_id, JobState.ABORTED, reason=(
                "interrupted (gonio scan stopped) during the simulated rig's calibration"))
            print(f"calibration job {job_id} interrupted and aborted ({row.done_angles} of "
                  f"{row.total_angles} angles measured); the scan had not started. The same "
                  "command again calibrates the simulated rig anew, then scans",
                  file=sys.stderr, flush=True)
        raise
    if final is JobState.COMPLETED:
        return None
    return f"calibration of the simulated rig {final.value}: {service.get_job(job_id).reason}"


SIM_SPECIMEN_SUFFIX = ".sim-specimen.json"
"""Beside a rig config written by ``gonio sim -o rig.toml``: ``rig.sim-specimen.json``, the
recipe of the simulated specimen (:func:`gonio.figures.describe_material`), so a scan of that
rig in another process (``gonio scan --rig``, ``gonio serve --rig``) records the truth and
``gonio render`` shows it beside the reconstruction."""


def sim_specimen_path(rig_config_path: Path) -> Path:
    """Where ``gonio sim`` writes the specimen recipe for ``rig_config_path``."""
    p = Path(rig_config_path)
    return p.with_name(p.stem + SIM_SPECIMEN_SUFFIX)


def write_sim_specimen(sim: Any) -> Path | None:
    """Write the recipe of ``sim``'s specimen beside its rig config; the path, or None when
    the specimen cannot be written down."""
    import json

    from gonio.figures import describe_material

    recipe = describe_material(sim.specimen.brdf)
    if recipe is None or sim.config_path is None:
        return None
    path = sim_specimen_path(sim.config_path)
    path.write_text(json.dumps(recipe))
    return path


def sim_specimen_truth(rig_config_path: Path, rig_config: Any) -> dict[str, Any] | None:
    """The simulated specimen's recipe for a rig config ``gonio sim`` wrote, when that
    simulator is the one answering (its specimen holder, Modbus device
    :data:`gonio.sim.rig.HOLDER_DEVICE_ID` on the lights' bus); None for a real rig (a recipe
    left beside a config later pointed at real devices is not the truth of what they see)."""
    import json

    from pymodbus.client import ModbusTcpClient

    from gonio.sim.rig import HOLDER_DEVICE_ID

    path = sim_specimen_path(rig_config_path)
    if not path.is_file() or not rig_config.lights:
        return None
    try:
        recipe = json.loads(path.read_text())
    except (OSError, ValueError):
        return None
    bus = rig_config.lights[0].modbus
    client = ModbusTcpClient(bus.host, port=bus.port, timeout=2, retries=0)
    try:
        if not client.connect():
            return None
        reply = client.read_holding_registers(0, count=2, device_id=HOLDER_DEVICE_ID)
        answered = not reply.isError()
    except Exception:  # no simulator there: a real device, or nothing
        answered = False
    finally:
        client.close()
    return recipe if answered and isinstance(recipe, dict) else None


SESSION_KEY_FILE = "sim-session.key"
"""The file of a ``gonio serve --sim`` data directory that keeps its session's API key."""

_SESSION_KEY = re.compile(r"[0-9a-f]{48}")


def session_key(data_dir: Path) -> tuple[str, bool]:
    """The API key of ``gonio serve --sim`` on ``data_dir`` when no keys are configured: the
    one kept in :data:`SESSION_KEY_FILE` (readable by its owner only), or a new one written
    there. A page left open (the key is in its tab) keeps working across a restart on the same
    data directory; a new key each start made it ask for one. Deleting the file makes a new
    key at the next start.

    Returns
    -------
    The key (48 hex digits: never starts with '-', which argparse would take for an option),
    and whether it was kept from an earlier start.
    """
    path = data_dir / SESSION_KEY_FILE
    try:
        kept = path.read_text(encoding="ascii").strip()
    except (OSError, UnicodeDecodeError):
        kept = ""
    if _SESSION_KEY.fullmatch(kept):
        return kept, True
    key = secrets.token_hex(24)
    data_dir.mkdir(parents=True, exist_ok=True)
    part = path.with_name(path.name + ".part")
    # Created owner-only before the key is in it, then renamed over any damaged one.
    fd = os.open(part, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "w", encoding="ascii") as f:
        f.write(key + "\n")
    os.replace(part, path)
    return key, False
