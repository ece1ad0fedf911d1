"""Where gonio keeps data when no folder is named, and one data directory per rig geometry."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path
from types import SimpleNamespace

import platformdirs
import pytest

from gonio.paths import DATA_ENV, geometry_key, scan_data_dir, sim_daemon_data_dir, user_data_root


class Rig:
    """The part of a rig configuration geometry_key reads: named directions and pairs."""

    def __init__(self, name: str, dirs: dict[str, tuple[float, float]],
                 pairs: list[tuple[str, str]]) -> None:
        self.rig = SimpleNamespace(name=name)
        self.dirs = dirs
        self.pairs = pairs

    def light(self, n: str) -> SimpleNamespace:
        return SimpleNamespace(theta_deg=self.dirs[n][0], phi_deg=self.dirs[n][1])

    sensor = light

    def pair_list(self) -> list[SimpleNamespace]:
        return [SimpleNamespace(light=a, sensor=b) for a, b in self.pairs]


RIG = Rig("Lab rig #2", {"L": (45.0, 0.0), "S": (30.0, 180.0)}, [("L", "S")])


def test_the_root_is_the_environment_folder_when_set(monkeypatch: pytest.MonkeyPatch,
                                                     tmp_path: Path) -> None:
    monkeypatch.setenv(DATA_ENV, str(tmp_path))
    assert user_data_root() == tmp_path
    assert sim_daemon_data_dir() == tmp_path / "serve-sim"
    assert not (tmp_path / "serve-sim").exists()  # nothing is created


def test_the_root_is_the_platform_folder_otherwise(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv(DATA_ENV, raising=False)
    assert user_data_root() == Path(platformdirs.user_data_dir("gonio"))


def test_geometry_key_is_a_hash_of_the_pairs_and_their_directions() -> None:
    # The key as defined: the first 8 hex digits of sha256 over the JSON list of
    # [light, sensor, light theta, light phi, sensor theta, sensor phi] per pair
    expected = hashlib.sha256(json.dumps([["L", "S", 45.0, 0.0, 30.0, 180.0]]).encode())
    assert geometry_key(RIG) == expected.hexdigest()[:8]


def test_moving_a_device_starts_a_fresh_directory() -> None:
    moved = Rig("Lab rig #2", {"L": (45.0, 0.0), "S": (30.5, 180.0)}, [("L", "S")])
    assert geometry_key(moved) != geometry_key(RIG)


def test_the_scan_directory_names_the_rig_safely(monkeypatch: pytest.MonkeyPatch,
                                                 tmp_path: Path) -> None:
    monkeypatch.setenv(DATA_ENV, str(tmp_path))
    assert scan_data_dir(RIG) == tmp_path / "scans" / f"Lab-rig-2-{geometry_key(RIG)}"
    nameless = Rig("../..", RIG.dirs, RIG.pairs)
    assert scan_data_dir(nameless).name == f"rig-{geometry_key(RIG)}"
