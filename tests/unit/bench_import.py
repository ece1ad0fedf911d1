"""Import a bench script as the scripts import each other (their folder on ``sys.path``), for
the unit tests of benches' own helpers."""

from __future__ import annotations

import importlib
import sys
from pathlib import Path
from types import ModuleType

BENCH = Path(__file__).resolve().parents[2] / "bench"


def import_bench(name: str) -> ModuleType:
    """The bench module ``name`` (e.g. ``"bench_unseen"``), with ``bench/`` on the path only
    while it and its sibling benches import."""
    sys.path.insert(0, str(BENCH))
    try:
        return importlib.import_module(name)
    finally:
        sys.path.remove(str(BENCH))
