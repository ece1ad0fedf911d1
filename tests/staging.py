"""Lay the source tree out as it is installed, for tools that cannot follow ``package-dir``.

pyproject.toml maps ``drivers/`` to ``gonio.drivers`` and ``sim/`` to ``gonio.sim``. Installs and
the interpreter honour that mapping; import-linter (grimp) and mypy walk the filesystem under
``gonio/`` and would not see those packages. They are run against this staged copy instead.
"""

from __future__ import annotations

import shutil
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
_IGNORE = shutil.ignore_patterns("__pycache__", "*.pyc", "static", "*.json")


def stage_installed_layout(dest: Path) -> Path:
    """Copy ``gonio/``, ``drivers/``, ``sim/`` into ``dest/gonio`` as installed; return ``dest``."""
    pkg = dest / "gonio"
    shutil.copytree(ROOT / "gonio", pkg, ignore=_IGNORE, dirs_exist_ok=True)
    shutil.copytree(ROOT / "drivers", pkg / "drivers", ignore=_IGNORE, dirs_exist_ok=True)
    shutil.copytree(ROOT / "sim", pkg / "sim", ignore=_IGNORE, dirs_exist_ok=True)
    return dest


if __name__ == "__main__":  # `python -m tests.staging DIR` for running mypy by hand
    import sys

    print(stage_installed_layout(Path(sys.argv[1])))
