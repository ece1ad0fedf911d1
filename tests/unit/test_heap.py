"""glibc's heap kept from growing across scans (gonio.heap), seen in a child process."""

from __future__ import annotations

import math
import subprocess
import sys

import pytest

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc, /proc")

# A freed 24 MB array raises glibc's dynamic mmap threshold to 24 MB (its limit is 32 MB), so
# the next 16 MB arrays come from the heap, and freeing one below another keeps its pages. With
# the threshold fixed they are mapped on their own, and freeing one gives its 16 MB back.
PROBE = """
import sys
import numpy as np
if sys.argv[1] == "bound":
    from gonio.heap import bound_heap
    if not bound_heap():
        print("nan")  # not glibc
        raise SystemExit
def rss_mb():
    for line in open("/proc/self/status"):
        if line.startswith("VmRSS"):
            return int(line.split()[1]) / 1024
big = np.ones(24 * 2**20 // 8)
del big
a, b = np.ones(16 * 2**20 // 8), np.ones(16 * 2**20 // 8)
before = rss_mb()
del a
print(before - rss_mb())
"""


def _released_mb(mode: str) -> float:
    out = subprocess.run([sys.executable, "-c", PROBE, mode], capture_output=True, text=True,
                         check=True, timeout=120)
    return float(out.stdout.strip())


def test_a_freed_array_goes_back_to_the_system_once_the_heap_is_bounded() -> None:
    bound = _released_mb("bound")
    if math.isnan(bound):
        pytest.skip("not glibc: mallopt is not there")
    assert _released_mb("default") < 4.0  # glibc's default keeps it: what grew the daemon
    assert bound > 12.0  # 16 MB, give or take a page table
