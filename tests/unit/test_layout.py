"""Every source module with behaviour has a test module named after it (tests/README.md).

A module's tests live at its mirrored path: ``gonio/a/b.py`` -> ``tests/unit/a/test_b.py`` (or a
folder ``tests/unit/a/b/``), ``drivers/x.py`` -> ``tests/unit/drivers/test_x.py``, ``sim/x.py``
-> ``tests/unit/sim/test_x.py`` (a leading ``_`` dropped). A module whose behaviour is only seen
across a real boundary (a driver against its simulator, an API route on loopback) may have it
at the same path under ``tests/system/`` instead. Every other module is listed below with the
reason; a new module that is in none of the lists fails here, so it comes with its tests.
"""

from __future__ import annotations

import importlib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]

# Modules with no behaviour of their own: exception classes, docstring-only package files,
# re-exports and wiring that any test importing them exercises. Each says why.
NO_BEHAVIOUR: dict[str, str] = {
    "gonio/__init__.py": "the version string from the installed metadata",
    "gonio/api/__init__.py": "package docstring",
    "gonio/api/deps.py": "FastAPI dependency aliases (guards are gonio/api/auth.py's)",
    "gonio/brdf/colour/__init__.py": "package docstring",
    "gonio/brdf/colour/errors.py": "one exception class",
    "gonio/brdf/design/__init__.py": "package docstring",
    "gonio/brdf/design/errors.py": "exception classes",
    "gonio/brdf/materials/__init__.py": "package docstring",
    "gonio/brdf/models/__init__.py": "package docstring",
    "gonio/brdf/pictures/__init__.py": "package docstring",
    "gonio/brdf/reconstruction/__init__.py": "package docstring",
    "gonio/brdf/reconstruction/errors.py": "one exception class",
    "gonio/brdf/tables/__init__.py": "package docstring",
    "gonio/plans/__init__.py": "package docstring",
    "drivers/__init__.py": "package docstring",
    "sim/__init__.py": "package docstring",
}

# Modules whose behaviour is pinned down by a test file of another name (written before this
# rule, or named for a boundary it crosses). Each maps to the file(s) that test it; renaming
# such a file to the mirrored name removes the entry.
TESTED_IN: dict[str, tuple[str, ...]] = {
    # A package's __init__ with entry points is tested in the package's folder (tests/README.md).
    "gonio/brdf/__init__.py": ("tests/unit/brdf/test_entry_points.py",),
    "gonio/cli/__init__.py": ("tests/unit/cli/test_errors.py",),
    "gonio/export/__init__.py": ("tests/unit/export/test_metadata.py",),
    # The API's routes are thin (parse, call the service, answer); they are requested over
    # loopback by the tests of what they serve (checked: each file requests one of the
    # router's paths). Their wiring and errors: tests/unit/api/test_app.py, test_errors.py.
    "gonio/api/routes_design.py": ("tests/system/api/test_design.py",),
    "gonio/api/routes_jobs.py": ("tests/system/api/test_scan_flow.py",
                                 "tests/system/api/test_start_races.py"),
    "gonio/api/routes_results.py": ("tests/system/api/test_scan_flow.py",
                                    "tests/system/api/test_time_api.py",
                                    "tests/system/api/test_colour.py"),
    "gonio/api/routes_standards.py": ("tests/system/api/test_colour_standards.py",
                                      "tests/system/api/test_browser_colour.py"),
    "gonio/api/routes_rig.py": ("tests/system/api/test_stage.py",
                                "tests/system/test_durable_state.py"),
    "gonio/api/routes_system.py": ("tests/system/api/test_scan_flow.py",
                                   "tests/system/api/test_bad_input.py"),
    "gonio/brdf/design/posterior.py": ("tests/unit/brdf/design/test_posterior_design.py",),
    "gonio/brdf/materials/measured.py": ("tests/unit/brdf/materials/test_imports.py",),
    "gonio/brdf/reconstruction/joint.py": (
        "tests/unit/brdf/reconstruction/test_reconstruct_joint.py",),
    "gonio/brdf/reconstruction/periodic.py": (
        "tests/unit/brdf/reconstruction/test_periodic_arc.py",),
    # A sub-command's module is run as a user runs it: main(["rig", ...]) or gonio(["rig", ...]).
    "gonio/cli/rig_command.py": ("tests/unit/test_rigdesign.py", "tests/system/test_lamps_off.py"),
    "gonio/cli/stage_command.py": ("tests/system/cli/test_stage.py",
                                   "tests/system/api/test_stage.py"),
    "gonio/cli/serve_command.py": ("tests/system/api/test_serve_command.py",),
    "gonio/cli/jobs_command.py": ("tests/unit/cli/test_scan_commands.py",),
    "gonio/cli/scan_report.py": ("tests/system/api/test_cli_daemon.py",
                                 "tests/unit/test_arc_check.py"),
    "gonio/cli/daemon_jobs.py": ("tests/system/api/test_cli_daemon_wait.py",),
    "gonio/cli/sim_command.py": ("tests/system/test_sim_rig.py",),
    "sim/dynamixel_device.py": ("tests/unit/sim/test_dynamixel_protocol.py",),
    "sim/rig.py": ("tests/system/test_sim_rig.py",),
}


def _source_modules() -> list[str]:
    return sorted(
        p.relative_to(ROOT).as_posix()
        for top in ("gonio", "drivers", "sim")
        for p in (ROOT / top).rglob("*.py")
    )


def _mirrored(module: str) -> list[Path]:
    """The paths where the module's own tests may live (tests/README.md)."""
    parts = module.removesuffix(".py").split("/")
    if parts[0] == "gonio":
        parts = parts[1:]
    *folder, name = parts
    name = name.lstrip("_")
    out = []
    for kind in ("unit", "system"):
        base = ROOT.joinpath("tests", kind, *folder)
        out += [base / f"test_{name}.py", base / name]
    return out


def _has_own_tests(module: str) -> bool:
    return any(p.exists() for p in _mirrored(module))


def test_every_module_with_behaviour_has_its_test_module() -> None:
    missing = [m for m in _source_modules()
               if not _has_own_tests(m) and m not in NO_BEHAVIOUR and m not in TESTED_IN]
    assert not missing, (
        "these modules have no test module at their mirrored path (tests/README.md, 'Where a "
        "test goes'): " + ", ".join(missing)
        + "; add tests/unit/.../test_<module>.py, or list the module in tests/unit/test_layout.py "
        "with the reason"
    )


@pytest.mark.parametrize("listing", ["NO_BEHAVIOUR", "TESTED_IN"])
def test_the_lists_name_only_modules_that_need_them(listing: str) -> None:
    """An entry for a module that is gone, or that now has its own tests, is stale."""
    entries = globals()[listing]
    modules = set(_source_modules())
    gone = sorted(set(entries) - modules)
    assert not gone, f"{listing} names modules that do not exist: {gone}"
    own = sorted(m for m in entries if _has_own_tests(m))
    assert not own, f"{listing} names modules that have their own test module now: {own}"


def _route_paths(dotted: str) -> list[str]:
    """The paths a routes module serves, each as a test would spell it: the whole path, or
    the part after its last parameter (``/api/v1/jobs/{job_id}/fit`` -> ``/fit``)."""
    router = importlib.import_module(dotted).router
    return [r.path.rsplit("}", 1)[-1] or r.path.split("{", 1)[0] for r in router.routes]


def test_the_files_named_as_testing_a_module_import_it() -> None:
    for module, files in TESTED_IN.items():
        dotted = module.removesuffix(".py").removesuffix("/__init__").replace("/", ".")
        if not dotted.startswith("gonio."):
            dotted = "gonio." + dotted
        parent, _, name = dotted.rpartition(".")
        command = name.removesuffix("_command") if name.endswith("_command") else None
        paths = _route_paths(dotted) if name.startswith("routes_") else []
        for f in files:
            text = (ROOT / f).read_text()
            runs = (command is not None and f'(["{command}"' in text) or any(
                p in text for p in paths)
            assert dotted in text or f"from {parent} import {name}" in text or runs, (
                f"{f} is listed as testing {module} but neither imports nor runs it")


def test_the_no_behaviour_modules_define_no_functions() -> None:
    """A module listed as having no behaviour holds no function of its own (exception classes,
    aliases and docstrings only); gonio/api/deps.py's one-line dependency is the exception."""
    for module in NO_BEHAVIOUR:
        if module == "gonio/api/deps.py":
            continue
        text = (ROOT / module).read_text()
        assert "\ndef " not in text and "\nasync def " not in text and "    def " not in text, (
            f"{module} defines a function: it has behaviour, so it needs its tests")
