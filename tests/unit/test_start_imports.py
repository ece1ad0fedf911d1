"""What a ``gonio`` process imports before it does anything: no SciPy; and for the light
commands (``gonio keys``, ``gonio jobs list``, the help of the commands outside the science
core) none of the heavy libraries: no FastAPI, NumPy, pydantic, h5py or device protocols.

``gonio NAME`` imports only NAME's command module (``gonio.cli.build_parser``), and a command
module imports at its top only what its parser needs. ``gonio serve`` imports the API app;
SciPy (about 0.4 s of CPU) loads with the first fit or interpolation instead, which many daemons
and commands never reach (a refusal, a calibration job, ``gonio rig lights-off``). The deferred
imports themselves run in every test of ``joint.solve_joint`` and
``periodic.periodic_pchip_rows`` (tests/unit/brdf/reconstruction/).
"""

from __future__ import annotations

import argparse
import hashlib
import importlib
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from gonio.cli import COMMAND_MODULES, build_parser


def test_the_daemon_and_the_cli_start_without_scipy() -> None:
    code = (
        "import sys\n"
        "import gonio.api.app, gonio.daemon, gonio.cli.serve_command, gonio.cli.sim_session\n"
        "import gonio.sim.rig\n"
        "from gonio.cli import build_parser\n"
        "build_parser()\n"
        "print(sorted(m for m in sys.modules if m.split('.')[0] == 'scipy'))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, timeout=120).stdout
    assert out.strip() == "[]"



# What only the commands that do real work need: the HTTP stack (the daemon), the numerical
# and file libraries (the science core, results), the device protocols (the rig).
HEAVY = ("fastapi", "starlette", "uvicorn", "pydantic", "numpy", "scipy", "h5py", "matplotlib",
         "pymodbus", "dynamixel_sdk", "serial")

# A ``gonio`` process that writes the names of every module it imported to the file given
# first, at exit (after --help too: argparse exits through SystemExit).
RECORDING_GONIO = (
    "import atexit, json, sys\n"
    "out = sys.argv.pop(1)\n"
    "def record() -> None:\n"
    "    with open(out, 'w') as f:\n"
    "        json.dump(sorted(sys.modules), f)\n"
    "atexit.register(record)\n"
    "from gonio.cli import main\n"
    "sys.exit(main())\n"
)


def run_gonio(tmp_path: Path, *argv: str) -> tuple[subprocess.CompletedProcess[str], set[str]]:
    """Run ``gonio ARGV`` in a child process: its result and the top-level packages it imported."""
    record = tmp_path / "modules.json"
    env = {**os.environ, "HOME": str(tmp_path / "home")}
    env.pop("GONIO_API_KEYS", None)
    done = subprocess.run([sys.executable, "-c", RECORDING_GONIO, str(record), *argv],
                          capture_output=True, text=True, timeout=300, env=env, cwd=tmp_path)
    return done, {m.split(".")[0] for m in json.loads(record.read_text())}


def test_keys_new_and_list_run_without_the_http_stack_or_the_science_core(
        tmp_path: Path) -> None:
    keys = tmp_path / "api-keys"
    done, imported = run_gonio(tmp_path, "keys", "new", "alice", "--keys-file", str(keys))
    assert done.returncode == 0, done.stderr
    assert imported.isdisjoint(HEAVY), sorted(imported & set(HEAVY))
    # The command did its job: the key printed once, its SHA-256 (hashlib, not gonio) stored.
    key = done.stdout.strip()
    assert keys.read_text() == f"alice sha256:{hashlib.sha256(key.encode()).hexdigest()}\n"

    done, imported = run_gonio(tmp_path, "keys", "list", "--keys-file", str(keys))
    assert done.returncode == 0, done.stderr
    assert imported.isdisjoint(HEAVY), sorted(imported & set(HEAVY))
    assert done.stdout == f"alice\t{keys}\tdigest\n" and key not in done.stdout

    # A refusal is still one line and exit code 2 (main's handlers work without pydantic).
    done, imported = run_gonio(tmp_path, "keys", "new", "two words", "--keys-file", str(keys))
    assert done.returncode == 2 and "use 1 to 64 letters" in done.stderr
    assert "Traceback" not in done.stderr
    assert imported.isdisjoint(HEAVY), sorted(imported & set(HEAVY))
    assert keys.read_text().splitlines() == [f"alice {stored_digest(key)}"]


def stored_digest(key: str) -> str:
    return "sha256:" + hashlib.sha256(key.encode()).hexdigest()


def test_keys_from_a_daemon_config_load_only_the_config_reader(tmp_path: Path) -> None:
    # --config reads the daemon config, which pydantic validates; nothing else heavy, and
    # never the API.
    light = set(HEAVY) - {"pydantic"}
    (tmp_path / "daemon.toml").write_text('[auth]\nkeys_file = "api-keys"\n')
    done, imported = run_gonio(tmp_path, "keys", "new", "lab", "--config",
                               str(tmp_path / "daemon.toml"))
    assert done.returncode == 0, done.stderr
    key = done.stdout.strip()
    assert (tmp_path / "api-keys").read_text() == f"lab {stored_digest(key)}\n"
    assert imported.isdisjoint(light), sorted(imported & light)
    done, imported = run_gonio(tmp_path, "keys", "list", "--config", str(tmp_path / "daemon.toml"))
    assert done.returncode == 0 and done.stdout.startswith("lab\t")
    assert imported.isdisjoint(light), sorted(imported & light)


def test_jobs_list_of_an_empty_store_loads_nothing_heavy(tmp_path: Path) -> None:
    from gonio.store import JobStore

    JobStore(tmp_path / "jobs.sqlite")
    done, imported = run_gonio(tmp_path, "jobs", "list", "--db", str(tmp_path / "jobs.sqlite"),
                               "--json")
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout) == []
    assert imported.isdisjoint(HEAVY), sorted(imported & set(HEAVY))


# The commands whose help needs none of the heavy libraries. Those of the science core
# (basis, library, simulate-scan, reconstruct, demo, design) read choices and defaults from
# numerical modules that import NumPy.
@pytest.mark.parametrize("command", ["scan", "jobs", "sim", "sim-place", "serve", "stage",
                                     "rig", "export", "keys", "render", "colour",
                                     "colour-chart"])
def test_help_of_a_light_command_loads_nothing_heavy(tmp_path: Path, command: str) -> None:
    done, imported = run_gonio(tmp_path, command, "--help")
    assert done.returncode == 0 and done.stdout.startswith(f"usage: gonio {command}")
    assert imported.isdisjoint(HEAVY), sorted(imported & set(HEAVY))


def _names(parser: argparse.ArgumentParser) -> set[str]:
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return set(sub.choices)


def test_each_command_module_registers_the_names_listed_for_it() -> None:
    # build_parser imports only the module listed for the command named: a name missing from
    # COMMAND_MODULES would make its command unreachable on its own.
    for module, names in COMMAND_MODULES.items():
        parser = argparse.ArgumentParser()
        importlib.import_module(module).register(parser.add_subparsers())
        assert _names(parser) == set(names), module
    every = [n for names in COMMAND_MODULES.values() for n in names]
    assert len(every) == len(set(every))


@pytest.mark.parametrize(("argv", "expected"), [
    (["keys", "list"], {"keys"}),
    (["color", "--help"], {"colour", "color", "colour-chart", "color-chart"}),
    (["sim-place", "white"], {"sim", "sim-place"}),
    (["--version"], set()),
    ([], None), (["--help"], None), (["-h", "keys"], None), (["keyz", "list"], None),
])
def test_the_parser_holds_the_named_command_or_all(argv: list[str],
                                                   expected: set[str] | None) -> None:
    every = {n for names in COMMAND_MODULES.values() for n in names}
    assert _names(build_parser(argv)) == (every if expected is None else expected)


def test_version_loads_no_command(tmp_path: Path) -> None:
    from gonio import __version__

    done, imported = run_gonio(tmp_path, "--version")
    assert done.returncode == 0 and done.stdout == f"gonio {__version__}\n"
    assert imported.isdisjoint(HEAVY), sorted(imported & set(HEAVY))
    assert not any(m.startswith("gonio.cli.") for m in json.loads(
        (tmp_path / "modules.json").read_text()))
