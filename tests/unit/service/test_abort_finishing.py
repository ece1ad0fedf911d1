"""Aborting a job while it is being finished: nothing written, nothing computing beside the next.

The finishing step runs in a thread that cannot be interrupted; the abort is a request it
honours at its next step. The basis provider here is a gate the test opens, so the job is held
in ``reconstructing`` for as long as the test needs, on any machine load.
"""

from __future__ import annotations

import asyncio
import threading
from pathlib import Path
from typing import Any

from gonio.basis_supply import BasisSupply
from gonio.jobstates import JobState
from gonio.plans.models import ExposureSettings, UniformPlan
from gonio.service import GonioService, JobRequest
from gonio.sim.memrig import MemRig
from gonio.store import JobStore

FAST = ExposureSettings(exposure_s=0.002, light_settle_s=0.0)


class GatedBasis:
    """A basis provider that blocks until :meth:`open`, then fails loudly if used further.

    If finishing ignored the abort it would go on to reconstruct with what this returns and
    the job would end ``failed``, not ``aborted``.
    """

    def __init__(self) -> None:
        self.entered = threading.Event()
        self._gate = threading.Event()
        self.calls = 0

    def __call__(self) -> Any:
        self.calls += 1
        self.entered.set()
        assert self._gate.wait(120), "the test never opened the gate"
        return object()  # not a basis: using it would fail the job

    def open(self) -> None:
        self._gate.set()


async def _wait_state(svc: GonioService, job_id: int, *states: JobState) -> JobState:
    for _ in range(6000):
        state = svc.get_job(job_id).state
        if state in states:
            return state
        await asyncio.sleep(0.02)
    raise AssertionError(f"job {job_id} never reached {states}: {svc.get_job(job_id)}")


def test_abort_while_finishing_writes_nothing_and_holds_the_next_job(tmp_path: Path) -> None:
    gate = GatedBasis()
    data = tmp_path / "d"
    svc = GonioService(JobStore(tmp_path / "jobs.sqlite"), MemRig(), basis=BasisSupply(gate),
                       data_dir=data)

    async def go() -> None:
        await svc.start()
        first = svc.submit(JobRequest(plan=UniformPlan(rotations=2, exposure=FAST)))
        second = svc.submit(JobRequest(plan=UniformPlan(rotations=2, exposure=FAST)))
        await _wait_state(svc, first.id, JobState.RECONSTRUCTING)
        assert await asyncio.to_thread(gate.entered.wait, 60)
        svc.abort(first.id)
        # The finishing thread is still inside the basis provider: the next job must not
        # start beside it, and the aborted job is not reported aborted before it stopped.
        await asyncio.sleep(0.3)
        assert svc.get_job(second.id).state is JobState.QUEUED
        assert svc.get_job(first.id).state is JobState.RECONSTRUCTING
        gate.open()
        assert await _wait_state(svc, first.id, JobState.ABORTED, JobState.FAILED,
                                 JobState.COMPLETED) is JobState.ABORTED
        # The next job runs and gets to its own finishing (the gate is open now).
        await _wait_state(svc, second.id, JobState.FAILED, JobState.COMPLETED)
        await svc.stop()

    asyncio.run(go())
    job = svc.get_job(1)
    # Its readings are whole: the reason says how to finish it after all (test_finishing.py).
    assert job.reason is not None
    assert job.reason.startswith("aborted by request while it was being finished; every "
                                 "reading is stored: 'gonio jobs rebuild 1 --db "), job.reason
    assert not (data / "results" / "job-1.h5").exists()
    # The first job's finishing loaded the basis; the second job's reused it (one load).
    assert gate.calls == 1
