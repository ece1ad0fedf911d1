"""Child process for the kill-and-restart tests: measure a job on a fresh simulated rig.

Usage: python _scan_child.py DB STAGE SEED ROTATIONS [FREEZE_AFTER [MATERIAL [ARC [KIND]]]].
Resumes the store's active job if there is one (as the daemon does after a crash), otherwise
creates it (uniform, ROTATIONS angles, ``arc`` ARC, default ``fixed``; with KIND ``adaptive``
the posterior rule from ROTATIONS first angles up to 12, planned with the small test bases of
``tests/unit/test_finishing_basis_switch.py``: ``EVEN`` as the default basis, ``ODD`` as the
one for specimens without twofold symmetry) on a rig holding MATERIAL (default: the
simulated rig's own). With FREEZE_AFTER the process stops dead (as if
hung) right after committing that many angles, so the test's SIGKILL lands mid-scan however busy
the machine is. The tests start it with :func:`start_child` and kill it with
:func:`kill_when_frozen`.
"""

from __future__ import annotations

import asyncio
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

from gonio.drivers.factory import build_rig
from gonio.engine import ScanEngine
from gonio.plans.models import AdaptivePlan, ExposureSettings, UniformPlan, parse_plan
from gonio.rigdescription import RigDescription
from gonio.sim.rig import SimRigOptions, start_sim_rig
from gonio.store import JobStore


def start_child(db: Path, seed: int, freeze_after: int = 0, *, stage: str = "dynamixel",
                rotations: int = 8, material: str | None = None,
                arc: str = "fixed", kind: str = "uniform") -> subprocess.Popen[str]:
    """This script in a child process (its stdout: the job's final state)."""
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[2])}
    argv = [str(db), stage, str(seed), str(rotations), str(freeze_after)]
    if material is not None or arc != "fixed" or kind != "uniform":
        argv += [material or "", arc, kind]
    return subprocess.Popen([sys.executable, __file__, *argv], stdout=subprocess.PIPE,
                            text=True, env=env)


def stopped(pid: int) -> bool:
    """True once the process is stopped (SIGSTOP): state 'T' in /proc/PID/stat."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return False
    return stat.rsplit(")", 1)[1].split()[0] in ("T", "t")


def kill_when_frozen(proc: subprocess.Popen[str], timeout_s: float = 300.0) -> None:
    """SIGKILL a child started with FREEZE_AFTER once it has stopped itself there; fails the
    test if it ended first (it was never mid-scan)."""
    deadline = time.monotonic() + timeout_s
    while not stopped(proc.pid) and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.05)
    assert proc.poll() is None, "the child ended before it could be killed mid-scan"
    proc.send_signal(signal.SIGKILL)
    proc.wait()


def _refiner(plan: Any, desc: RigDescription) -> Any:
    """The posterior rule of an adaptive plan, with the small test bases (module notes)."""
    from gonio.plans.checked import check_plan
    from gonio.refinement import PosteriorRefiner
    from tests.unit.test_finishing_basis_switch import EVEN, ODD

    return PosteriorRefiner(lambda: EVEN, desc, check_plan(plan, desc).pairs,
                            asymmetric_provider=lambda: ODD)


async def main(db: str, stage: str, seed: int, rotations: int, freeze_after: int = 0,
               material: str | None = None, arc: str = "fixed", kind: str = "uniform") -> int:
    with start_sim_rig(SimRigOptions(stage=stage, time_scale=10.0, seed=seed,
                                     material=material or None)) as sim:
        rig = build_rig(sim.config)
        desc = RigDescription.from_rig(rig)
        store = JobStore(db)
        active = store.active_jobs()
        if active:
            store.reconcile(lambda j: None)
            job = active[0]
            plan = parse_plan(job.plan)
        else:
            exposure = ExposureSettings(exposure_s=0.02, light_settle_s=0.0, dark="every_angle")
            if kind == "adaptive":
                plan = AdaptivePlan.model_validate({
                    "initial_rotations": rotations, "max_rotations": 12, "min_gain": 1e-9,
                    "arc": arc, "exposure": exposure})
            else:
                plan = UniformPlan.model_validate({
                    "rotations": rotations, "arc": arc,  # validated: from the command line
                    "exposure": exposure})
            job = store.create_job(kind=plan.kind, specimen="sim",
                                   plan=plan.model_dump(mode="json"),
                                   rig=desc.model_dump(mode="json"))
        if freeze_after > 0:
            def freeze(ev: Any) -> None:
                if ev.type == "progress" and ev.data.get("done", 0) >= freeze_after:
                    os.kill(os.getpid(), signal.SIGSTOP)  # the test kills it from here

            store.add_listener(freeze)
        async with rig:
            refiner = _refiner(plan, desc) if plan.kind == "adaptive" else None
            state = await ScanEngine(rig, store, job.id, plan, desc, refiner=refiner).run()
        print(state.value, flush=True)
    return 0


if __name__ == "__main__":
    db, stage, seed, rotations = sys.argv[1:5]
    freeze_after = int(sys.argv[5]) if len(sys.argv) > 5 else 0
    material = sys.argv[6] or None if len(sys.argv) > 6 else None
    arc = sys.argv[7] if len(sys.argv) > 7 else "fixed"
    kind = sys.argv[8] if len(sys.argv) > 8 else "uniform"
    raise SystemExit(asyncio.run(main(db, stage, int(seed), int(rotations), freeze_after,
                                      material, arc, kind)))
