"""Where gonio keeps data when the user names no folder.

``$GONIO_DATA_DIR`` if set, else the platform's user data folder (``platformdirs``; on Linux
``~/.local/share/gonio``). Inside it:

* ``scans/<rig>-<geometry hash>/``: the data directory of ``gonio scan`` for one rig geometry
  and sensor set (job store ``gonio.sqlite``, ``results/job-<id>.h5``, ``calibration.json``);
* ``serve-sim/``: the data directory of ``gonio serve --sim``;
* ``scan-sim/<rig>-<geometry hash>/``: the data directory of ``gonio scan --sim``, apart from
  ``scans/`` so its own calibrations do not replace those of a ``gonio sim`` rig of the same
  geometry (``gonio scan --rig`` on the README's simulated rig);
* ``library/``: the user library of imported tables, unless ``$GONIO_LIBRARY_DIR`` names
  another (``gonio.brdf.materials.measured.user_library_dir``).

A data directory has the daemon's layout (docs/file-formats.md, "Data directory").
"""

from __future__ import annotations

import hashlib
import json
import os
import re
from pathlib import Path
from typing import Any

import platformdirs

DATA_ENV = "GONIO_DATA_DIR"


def user_data_root() -> Path:
    """gonio's user data folder: ``$GONIO_DATA_DIR`` if set, else the platform's (not created)."""
    env = os.environ.get(DATA_ENV)
    return Path(env) if env else Path(platformdirs.user_data_dir("gonio"))


def _pair_geometry(rig_config: Any) -> list[list[Any]]:
    """Each measured pair's names and its light's and sensor's directions (degrees)."""
    return [
        [p.light, p.sensor,
         rig_config.light(p.light).theta_deg, rig_config.light(p.light).phi_deg,
         rig_config.sensor(p.sensor).theta_deg, rig_config.sensor(p.sensor).phi_deg]
        for p in rig_config.pair_list()
    ]


def geometry_key(rig_config: Any) -> str:
    """Short stable hash of a rig's measured pairs, device directions and sensor channels.

    A calibration is only valid for the geometry and the sensors it was measured with, so
    ``gonio scan`` keeps one data directory per rig: moving a device, changing the pairs or
    reading with other sensors (31-band spectrometers where RGB photodiodes were, as the
    simulated rig does for a spectral material) starts a fresh one, and switching back finds
    the old calibration instead of measuring it again.
    """
    sensors = sorted({p.sensor for p in rig_config.pair_list()})
    channels = [[name, list(rig_config.sensor(name).channels)] for name in sensors]
    doc = {"pairs": _pair_geometry(rig_config), "channels": channels}
    return hashlib.sha256(json.dumps(doc).encode()).hexdigest()[:8]


def legacy_geometry_key(rig_config: Any) -> str:
    """The key of gonio before 2026-11-29: pairs and directions only, one data directory for
    every sensor set of a geometry (:func:`scan_data_dir` still finds it)."""
    return hashlib.sha256(json.dumps(_pair_geometry(rig_config)).encode()).hexdigest()[:8]


def _rig_dir_name(rig_config: Any) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "-", rig_config.rig.name).strip("-.") or "rig"


def scan_data_dir(rig_config: Any) -> Path:
    """Default data directory of ``gonio scan`` on ``rig_config`` (not created).

    ``scans/<rig>-<geometry_key>``. Until that folder exists, a folder of the legacy key
    (:func:`legacy_geometry_key`) holding a calibration for the rig's sensors is used instead,
    so a rig calibrated before the key held the sensors' channels keeps its calibration and
    its jobs. A legacy folder calibrated for other sensors is left to them, and one without a
    calibration to no one: were it taken by every sensor set, the first set to calibrate there
    would move the others out of it, from under a daemon started on it.
    """
    scans = user_data_root() / "scans"
    name = _rig_dir_name(rig_config)
    own = scans / f"{name}-{geometry_key(rig_config)}"
    if own.is_dir():
        return own
    legacy = scans / f"{name}-{legacy_geometry_key(rig_config)}"
    if legacy.is_dir() and _calibration_fits_sensors(legacy, rig_config):
        return legacy
    return own


CALIBRATION_NAME = "calibration.json"
"""A data directory's calibration file (``gonio.calibration.CALIBRATION_FILE``)."""


def _calibration_fits_sensors(data_dir: Path, rig_config: Any) -> bool:
    """Whether ``data_dir`` holds a calibration of the rig's sensors: factors for at least
    one pair, each naming one of the rig's sensors with as many channels as it reads (the
    file records counts, not channel names). False without one or with one that cannot be
    read, so that the answer cannot change until a calibration of these sensors is written
    there, which only a rig that chose the folder does."""
    wanted = {s.name: len(s.channels) for s in getattr(rig_config, "sensors", None) or ()}
    try:
        pairs = json.loads((data_dir / CALIBRATION_NAME).read_text()).get("pairs") or []
        counts = [(str(p["sensor"]), len(p["factor"])) for p in pairs]
    except (OSError, ValueError, AttributeError, KeyError, TypeError):
        return False
    return bool(counts) and all(wanted.get(sensor) == n for sensor, n in counts)


STORE_NAME = "gonio.sqlite"
"""The job store's file name in a data directory (``gonio.daemon.STORE_FILE``)."""


def store_places() -> list[str]:
    """Where :func:`default_stores` looks for job stores, as patterns to tell a user."""
    root = user_data_root()
    return [str(root / "scans" / "*" / STORE_NAME), str(root / "scan-sim" / "*" / STORE_NAME),
            str(root / "serve-sim" / STORE_NAME), str(Path(STORE_NAME))]


def default_stores() -> list[Path]:
    """The job stores in gonio's default data directories (each of ``gonio scan``'s and
    ``gonio serve --sim``'s) and ``./gonio.sqlite``, those that exist."""
    root = user_data_root()
    found = sorted((root / "scans").glob(f"*/{STORE_NAME}"))
    found += sorted((root / "scan-sim").glob(f"*/{STORE_NAME}"))
    found += [p for p in (root / "serve-sim" / STORE_NAME, Path(STORE_NAME)) if p.is_file()]
    return [p for p in found if p.is_file()]


def sim_scan_data_dir(rig_config: Any) -> Path:
    """Default data directory of ``gonio scan --sim`` on its simulated rig ``rig_config`` (not
    created): ``scan-sim/<rig>-<geometry_key>``. Not ``scans/``, which a ``gonio sim`` rig of
    the same geometry (the README's) uses: a ``gonio scan --sim`` at another exposure
    calibrated there and replaced that rig's calibration, and listed its unfinished jobs."""
    return user_data_root() / "scan-sim" / f"{_rig_dir_name(rig_config)}-{geometry_key(rig_config)}"


def sim_daemon_data_dir() -> Path:
    """Default data directory of ``gonio serve --sim`` (not created)."""
    return user_data_root() / "serve-sim"
