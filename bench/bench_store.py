"""Readings per second the job store sustains, committed one stage angle at a time.

Run: ``.venv/bin/python bench/bench_store.py [--angles 500] [--per-angle 12]``
Prints readings/s for durable (synchronous=FULL) and crash-safe (NORMAL) modes.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

from gonio.store import JobStore, ReadingRow


def run(durable: bool, angles: int, per_angle: int) -> float:
    with tempfile.TemporaryDirectory() as d:
        store = JobStore(Path(d) / "bench.sqlite", durable=durable)
        job = store.create_job(kind="uniform", specimen="bench", plan={}, rig={})
        store.add_steps(job.id, [(k, 0, k * 0.5, k * 0.5) for k in range(angles)])
        t0 = time.perf_counter()
        for k in range(angles):
            rows = [ReadingRow(k, k * 0.5, k * 0.5, f"L{i % 3}", f"S{i}", (1.0, 2.0, 3.0),
                               (0.1, 0.1, 0.1), 0.01, 1, False, time.time())
                    for i in range(per_angle)]
            store.commit_angle(job.id, k, k * 0.5, rows)
        dt = time.perf_counter() - t0
        assert store.reading_count(job.id) == angles * per_angle
        store.close()
        return angles * per_angle / dt


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--angles", type=int, default=500)
    ap.add_argument("--per-angle", type=int, default=12)
    args = ap.parse_args()
    print(f"{'mode':<8} {'readings/s':>11} {'checkpoints/s':>14}")
    for durable in (True, False):
        rate = run(durable, args.angles, args.per_angle)
        print(f"{'FULL' if durable else 'NORMAL':<8} {rate:>11.0f} {rate / args.per_angle:>14.0f}")


if __name__ == "__main__":
    main()
