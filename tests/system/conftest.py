"""Every test under ``tests/system/`` is a system test (marker ``system``), so
``pytest -m "not system"`` runs only the in-process part whatever a file declares itself."""

from __future__ import annotations

from pathlib import Path

import pytest

_HERE = Path(__file__).resolve().parent


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    for item in items:
        if item.path.is_relative_to(_HERE):
            item.add_marker(pytest.mark.system)
