"""Where gonio keeps data when no folder is named, and one data directory per rig geometry."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path
from types import SimpleNamespace

import platformdirs
import pytest

from gonio.paths import (
    DATA_ENV,
    geometry_key,
    legacy_geometry_key,
    scan_data_dir,
    sim_daemon_data_dir,
    user_data_root,
)


class Rig:
    """The part of a rig configuration geometry_key reads: named directions, each sensor's
    channels, and pairs."""

    def __init__(self, name: str, dirs: dict[str, tuple[float, float]],
                 pairs: list[tuple[str, str]], channels: tuple[str, ...] = ("R", "G", "B")
                 ) -> None:
        self.rig = SimpleNamespace(name=name)
        self.dirs = dirs
        self.pairs = pairs
        self.channels = list(channels)
        self.sensors = [SimpleNamespace(name=s, channels=self.channels)
                        for s in sorted({b for _, b in pairs})]

    def light(self, n: str) -> SimpleNamespace:
        return SimpleNamespace(theta_deg=self.dirs[n][0], phi_deg=self.dirs[n][1],
                               channels=self.channels)

    sensor = light

    def pair_list(self) -> list[SimpleNamespace]:
        return [SimpleNamespace(light=a, sensor=b) for a, b in self.pairs]


RIG = Rig("Lab rig #2", {"L": (45.0, 0.0), "S": (30.0, 180.0)}, [("L", "S")])
BANDS = tuple(f"{nm}nm" for nm in range(400, 710, 10))
SPECTRAL = Rig("Lab rig #2", RIG.dirs, RIG.pairs, BANDS)


def test_the_root_is_the_environment_folder_when_set(monkeypatch: pytest.MonkeyPatch,
                                                     tmp_path: Path) -> None:
    monkeypatch.setenv(DATA_ENV, str(tmp_path))
    assert user_data_root() == tmp_path
    assert sim_daemon_data_dir() == tmp_path / "serve-sim"
    assert not (tmp_path / "serve-sim").exists()  # nothing is created


def test_the_root_is_the_platform_folder_otherwise(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv(DATA_ENV, raising=False)
    assert user_data_root() == Path(platformdirs.user_data_dir("gonio"))


def test_geometry_key_is_a_hash_of_the_pairs_their_directions_and_channels() -> None:
    # The key as defined: the first 8 hex digits of sha256 over the JSON of {"pairs": per
    # pair [light, sensor, light theta, light phi, sensor theta, sensor phi], "channels": per
    # sensor of a pair, by name, [sensor, its channels]}
    doc = {"pairs": [["L", "S", 45.0, 0.0, 30.0, 180.0]], "channels": [["S", ["R", "G", "B"]]]}
    expected = hashlib.sha256(json.dumps(doc).encode())
    assert geometry_key(RIG) == expected.hexdigest()[:8]
    # gonio before 2026-11-29 hashed the pairs' list alone
    legacy = hashlib.sha256(json.dumps([["L", "S", 45.0, 0.0, 30.0, 180.0]]).encode())
    assert legacy_geometry_key(RIG) == legacy.hexdigest()[:8]
    assert legacy_geometry_key(SPECTRAL) == legacy_geometry_key(RIG)


def test_other_sensors_start_their_own_directory(monkeypatch: pytest.MonkeyPatch,
                                                 tmp_path: Path) -> None:
    # An RGB and a 31-band sensor set on one geometry shared a folder: each switch found the
    # other's calibration and measured its own again (gonio scan --sim with a spectral
    # material and without).
    monkeypatch.setenv(DATA_ENV, str(tmp_path))
    assert geometry_key(SPECTRAL) != geometry_key(RIG)
    assert scan_data_dir(SPECTRAL) != scan_data_dir(RIG)


def _legacy_folder(root: Path, n_channels: int | None) -> Path:
    """A data directory of the legacy key, with a calibration of ``n_channels`` per pair (none
    when None), as gonio before 2026-11-29 wrote it."""
    folder = root / "scans" / f"Lab-rig-2-{legacy_geometry_key(RIG)}"
    folder.mkdir(parents=True)
    if n_channels is not None:
        (folder / "calibration.json").write_text(json.dumps(
            {"pairs": [{"light": "L", "sensor": "S", "factor": [5.3e-06] * n_channels}]}))
    return folder


def test_a_legacy_folder_calibrated_for_these_sensors_is_kept(
        monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.setenv(DATA_ENV, str(tmp_path))
    legacy = _legacy_folder(tmp_path, 3)
    assert scan_data_dir(RIG) == legacy  # the RGB rig keeps its calibration and its jobs
    assert scan_data_dir(SPECTRAL).name == f"Lab-rig-2-{geometry_key(SPECTRAL)}"


def test_a_legacy_folder_calibrated_for_other_sensors_is_left_to_them(
        monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.setenv(DATA_ENV, str(tmp_path))
    legacy = _legacy_folder(tmp_path, len(BANDS))
    assert scan_data_dir(SPECTRAL) == legacy
    assert scan_data_dir(RIG).name == f"Lab-rig-2-{geometry_key(RIG)}"


def test_a_legacy_folder_without_calibration_is_no_ones(monkeypatch: pytest.MonkeyPatch,
                                                        tmp_path: Path) -> None:
    """Taken by both sensor sets, the first to calibrate in it moved the other out of it
    (from under a daemon started there): it is neither's, and each set's folder is stable
    whatever the other writes."""
    monkeypatch.setenv(DATA_ENV, str(tmp_path))
    legacy = _legacy_folder(tmp_path, None)
    before = scan_data_dir(RIG), scan_data_dir(SPECTRAL)
    assert legacy not in before
    (legacy / "calibration.json").write_text(json.dumps(
        {"pairs": [{"light": "L", "sensor": "S", "factor": [5.3e-06] * len(BANDS)}]}))
    assert scan_data_dir(RIG) == before[0]  # the RGB rig's folder did not move


def test_a_legacy_calibration_of_unknown_sensors_or_unreadable_is_not_taken(
        monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.setenv(DATA_ENV, str(tmp_path))
    legacy = _legacy_folder(tmp_path, None)
    own = tmp_path / "scans" / f"Lab-rig-2-{geometry_key(RIG)}"
    for text in (json.dumps({"pairs": [{"light": "L", "sensor": "X", "factor": [1e-6] * 3}]}),
                 json.dumps({"pairs": []}), json.dumps([1, 2]), "{not json"):
        (legacy / "calibration.json").write_text(text)
        assert scan_data_dir(RIG) == own, text


def test_the_own_folder_wins_once_it_exists(monkeypatch: pytest.MonkeyPatch,
                                            tmp_path: Path) -> None:
    monkeypatch.setenv(DATA_ENV, str(tmp_path))
    _legacy_folder(tmp_path, 3)
    own = tmp_path / "scans" / f"Lab-rig-2-{geometry_key(RIG)}"
    own.mkdir()
    assert scan_data_dir(RIG) == own


def test_moving_a_device_starts_a_fresh_directory() -> None:
    moved = Rig("Lab rig #2", {"L": (45.0, 0.0), "S": (30.5, 180.0)}, [("L", "S")])
    assert geometry_key(moved) != geometry_key(RIG)


def test_the_scan_directory_names_the_rig_safely(monkeypatch: pytest.MonkeyPatch,
                                                 tmp_path: Path) -> None:
    monkeypatch.setenv(DATA_ENV, str(tmp_path))
    assert scan_data_dir(RIG) == tmp_path / "scans" / f"Lab-rig-2-{geometry_key(RIG)}"
    nameless = Rig("../..", RIG.dirs, RIG.pairs)
    assert scan_data_dir(nameless).name == f"rig-{geometry_key(RIG)}"
