"""Project-level contracts: import directions, README commands, packaging layout."""

from __future__ import annotations

import os
import re
import subprocess
import sys
import tomllib
from pathlib import Path
from typing import Any

import pytest

from tests.staging import stage_installed_layout

ROOT = Path(__file__).resolve().parents[2]


def _quick_start_commands() -> list[str]:
    text = (ROOT / "README.md").read_text()
    section = text.split("## Quick start", 1)[1]
    block = re.search(r"```(?:bash|sh)?\n(.*?)```", section, re.S)
    assert block, "README Quick start has no code block"
    return [line for line in block.group(1).splitlines() if line.strip()]


@pytest.fixture(scope="module")
def staged(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return stage_installed_layout(tmp_path_factory.mktemp("staged"))


def _tool(name: str) -> Path:
    exe = Path(sys.executable).with_name(name)
    if not exe.exists():
        pytest.skip(f"{name} is not installed (pip install -e '.[test]')")
    return exe


def test_import_contracts_hold(staged: Path) -> None:
    """import-linter enforces the import directions of docs/architecture.md (pyproject.toml)."""
    proc = subprocess.run(
        [str(_tool("lint-imports")), "--config", str(ROOT / "pyproject.toml")],
        cwd=staged, capture_output=True, text=True, timeout=120,
        env={**os.environ, "PYTHONPATH": str(staged)},
    )
    assert proc.returncode == 0, proc.stdout[-4000:] + proc.stderr[-2000:]


def _layers_contract() -> dict[str, Any]:
    config = tomllib.loads((ROOT / "pyproject.toml").read_text())
    for contract in config["tool"]["importlinter"]["contracts"]:
        if contract["type"] == "layers" and contract.get("containers") == ["gonio"]:
            return dict(contract)
    raise AssertionError("pyproject.toml has no layers contract over the gonio package")


def test_every_module_has_a_layer() -> None:
    """A new top-level module or package must be given its place in the house's layers
    (docs/architecture.md), or an upward import from it would go unchecked."""
    named = {m.strip() for row in _layers_contract()["layers"] for m in row.split("|")}
    top = {p.stem for p in (ROOT / "gonio").glob("*.py") if p.stem != "__init__"}
    top |= {p.name for p in (ROOT / "gonio").iterdir()
            if (p / "__init__.py").exists()}
    top |= {"drivers", "sim"}  # installed as gonio.drivers and gonio.sim (package-dir)
    assert top - named == set(), f"modules with no layer in pyproject.toml: {sorted(top - named)}"
    assert named - top == set(), f"layers name modules that do not exist: {sorted(named - top)}"


def test_an_upward_import_breaks_the_layers(staged: Path, tmp_path: Path) -> None:
    """The contract is not vacuous: the engine importing the service (up three rows) fails."""
    import shutil

    copy = tmp_path / "staged"
    shutil.copytree(staged, copy)
    with (copy / "gonio" / "engine.py").open("a") as f:
        f.write("\nimport gonio.service  # noqa: E402,F401\n")
    proc = subprocess.run(
        [str(_tool("lint-imports")), "--config", str(ROOT / "pyproject.toml")],
        cwd=copy, capture_output=True, text=True, timeout=120,
        env={**os.environ, "PYTHONPATH": str(copy)},
    )
    assert proc.returncode != 0
    assert "Layers" in proc.stdout and "BROKEN" in proc.stdout


def test_mypy_is_clean(staged: Path) -> None:
    """Type-check the installed layout with the settings of pyproject.toml."""
    proc = subprocess.run(
        [str(_tool("mypy")), "--config-file", str(ROOT / "pyproject.toml"), "-p", "gonio"],
        cwd=staged, capture_output=True, text=True, timeout=600,
        env={**os.environ, "MYPYPATH": str(staged)},
    )
    assert proc.returncode == 0, proc.stdout[-6000:]


def test_ruff_is_clean() -> None:
    proc = subprocess.run(
        [str(_tool("ruff")), "check", "gonio", "drivers", "sim", "tests", "bench"],
        cwd=ROOT, capture_output=True, text=True, timeout=120,
    )
    assert proc.returncode == 0, proc.stdout[-6000:]


def test_readme_has_exactly_two_setup_commands() -> None:
    commands = _quick_start_commands()
    assert len(commands) == 2, commands
    assert all(c.startswith("python3 -m venv .venv") for c in commands)


def test_ci_runs_the_readme_test_command() -> None:
    test_command = _quick_start_commands()[1]
    ci = (ROOT / ".ci" / "run").read_text()
    assert test_command in ci, "the README's test command and .ci/run have drifted apart"


def test_drivers_and_sim_map_into_the_gonio_namespace() -> None:
    import gonio.drivers
    import gonio.sim

    assert Path(gonio.drivers.__file__).parent.name == "drivers"
    assert Path(gonio.sim.__file__).parent.name == "sim"


def _setuptools_config() -> dict[str, Any]:
    return dict(tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"])


def _source_packages() -> dict[str, Path]:
    """Installed package name -> source folder, found by walking the tree (as installed)."""
    roots = {"gonio": ROOT / "gonio", "gonio.drivers": ROOT / "drivers", "gonio.sim": ROOT / "sim"}
    found: dict[str, Path] = {}
    for name, root in roots.items():
        for init in root.rglob("__init__.py"):
            rel = init.parent.relative_to(root).parts
            found[".".join((name, *rel))] = init.parent
    return found


def test_pyproject_lists_every_package() -> None:
    # The package list is explicit (package-dir maps drivers/ and sim/ into gonio, which
    # setuptools' find cannot express); a subpackage missing from it imports from a checkout
    # but is absent from a wheel.
    listed = set(_setuptools_config()["packages"])
    assert listed == set(_source_packages()), "pyproject [tool.setuptools] packages is stale"


def test_pyproject_ships_every_data_file() -> None:
    # Every non-Python file inside a package folder must match that package's package-data,
    # or a non-editable install leaves it behind (the measured materials, the page, ...).
    package_data: dict[str, list[str]] = _setuptools_config().get("package-data", {})
    packages = _source_packages()
    for name, folder in packages.items():
        subpackages = [f for n, f in packages.items() if n != name and f.is_relative_to(folder)]
        for path in folder.rglob("*"):
            if (not path.is_file() or path.suffix in {".py", ".pyc"}
                    or "__pycache__" in path.parts
                    or any(path.is_relative_to(s) for s in subpackages)):
                continue
            rel = path.relative_to(folder)
            assert any(rel.match(pattern) for pattern in package_data.get(name, [])), (
                f"{path.relative_to(ROOT)} is not in package-data of {name}"
            )


def _imported_top_level_modules(folder: Path) -> set[str]:
    """Top-level modules imported anywhere in ``folder``'s Python files (also lazily, inside
    functions: a command's import at run time fails just the same)."""
    import ast

    names: set[str] = set()
    for path in folder.rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Import):
                names.update(a.name.split(".")[0] for a in node.names)
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                names.add(node.module.split(".")[0])
    return names


def test_the_plain_install_brings_every_module_the_commands_import() -> None:
    # The README's first command installs with `pip install -e .` and then runs the commands
    # (gonio stage/scan --daemon among them): a third-party module they import that only the
    # test extra brings crashes them with ModuleNotFoundError (httpx did). Modules behind an
    # extra of their own (mitsuba: rgl) are imported under a guard that says so.
    from importlib.metadata import packages_distributions

    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]

    def dist_name(requirement: str) -> str:
        return re.split(r"[<>=!~; \[]", requirement, maxsplit=1)[0].lower().replace("_", "-")

    from importlib.metadata import PackageNotFoundError, requires

    # The main dependencies and what they bring themselves (starlette comes with fastapi).
    main: set[str] = set()
    todo = [dist_name(r) for r in project["dependencies"]]
    while todo:
        name = todo.pop()
        if name in main:
            continue
        main.add(name)
        try:
            todo += [dist_name(r) for r in requires(name) or [] if "extra ==" not in r]
        except PackageNotFoundError:
            continue
    guarded = {dist_name(r) for extra, reqs in project["optional-dependencies"].items()
               if extra != "test" for r in reqs}
    dists = packages_distributions()
    missing = []
    for root in (ROOT / "gonio", ROOT / "drivers", ROOT / "sim"):
        for module in _imported_top_level_modules(root):
            if module in sys.stdlib_module_names or module == "gonio":
                continue
            owners = {d.lower().replace("_", "-") for d in dists.get(module, [])}
            assert owners, f"{module} (imported in {root.name}/) is not installed"
            if not owners & (main | guarded):
                missing.append(f"{module} ({', '.join(sorted(owners))})")
    assert not missing, f"imported by gonio but only in the test extra or nowhere: {missing}"


def test_readme_says_what_the_gltf_validator_tests_need() -> None:
    # The glTF tests skip without `npm install` in tests/gltf: a reader of the README's test
    # command must learn that from the README, not from a skip line.
    gltf_test = (ROOT / "tests" / "unit" / "export" / "test_gltf.py").read_text()
    assert "npm install" in gltf_test and "tests/gltf" in str(ROOT / "tests" / "gltf")
    quick_start = (ROOT / "README.md").read_text().split("## Quick start", 1)[1]
    quick_start = quick_start.split("\n## ", 1)[0]
    assert "(cd tests/gltf &&\nnpm install)" in quick_start or \
        "(cd tests/gltf && npm install)" in quick_start, "README: the glTF tests' npm install"
