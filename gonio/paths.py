"""Where gonio keeps data when the user names no folder.

``$GONIO_DATA_DIR`` if set, else the platform's user data folder (``platformdirs``; on Linux
``~/.local/share/gonio``). Inside it:

* ``scans/<rig>-<geometry hash>/``: the data directory of ``gonio scan`` for one rig geometry
  (job store ``gonio.sqlite``, ``results/job-<id>.h5``, ``calibration.json``);
* ``serve-sim/``: the data directory of ``gonio serve --sim``;
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


def geometry_key(rig_config: Any) -> str:
    """Short stable hash of a rig's measured pairs and device directions.

    A calibration is only valid for the geometry it was measured on, so ``gonio scan`` keeps
    one data directory per geometry: moving a device or changing the pairs starts a fresh one.
    """
    pairs = [
        [p.light, p.sensor,
         rig_config.light(p.light).theta_deg, rig_config.light(p.light).phi_deg,
         rig_config.sensor(p.sensor).theta_deg, rig_config.sensor(p.sensor).phi_deg]
        for p in rig_config.pair_list()
    ]
    return hashlib.sha256(json.dumps(pairs).encode()).hexdigest()[:8]


def scan_data_dir(rig_config: Any) -> Path:
    """Default data directory of ``gonio scan`` on ``rig_config`` (not created)."""
    name = re.sub(r"[^A-Za-z0-9_.-]+", "-", rig_config.rig.name).strip("-.") or "rig"
    return user_data_root() / "scans" / f"{name}-{geometry_key(rig_config)}"


STORE_NAME = "gonio.sqlite"
"""The job store's file name in a data directory (``gonio.daemon.STORE_FILE``)."""


def store_places() -> list[str]:
    """Where :func:`default_stores` looks for job stores, as patterns to tell a user."""
    root = user_data_root()
    return [str(root / "scans" / "*" / STORE_NAME), str(root / "serve-sim" / STORE_NAME),
            str(Path(STORE_NAME))]


def default_stores() -> list[Path]:
    """The job stores in gonio's default data directories (each of ``gonio scan``'s and
    ``gonio serve --sim``'s) and ``./gonio.sqlite``, those that exist."""
    root = user_data_root()
    found = sorted((root / "scans").glob(f"*/{STORE_NAME}"))
    found += [p for p in (root / "serve-sim" / STORE_NAME, Path(STORE_NAME)) if p.is_file()]
    return [p for p in found if p.is_file()]


def sim_daemon_data_dir() -> Path:
    """Default data directory of ``gonio serve --sim`` (not created)."""
    return user_data_root() / "serve-sim"
