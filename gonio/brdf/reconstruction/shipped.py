"""The synthetic basis shipped with gonio, and the fingerprint that ties it to the code.

Building the synthetic library (175 analytic materials tabulated on the 5 degree grid) and
learning a basis from it takes about two minutes on two cores, yet the result is a few
megabytes. So gonio ships the expensive part, the synthetic basis of
:func:`gonio.brdf.reconstruction.basis.synthetic_basis` with :data:`SHIPPED_COMPONENTS`
components, in ``data/synthetic-basis.npz`` beside this module (``Q`` and ``ph_prior`` in
float32; the rounding, a few parts in 1e8, is far below measurement noise). The default basis
folds the shipped measured materials and the user's imports into it
(:func:`~gonio.brdf.reconstruction.basis.fold_in`, seconds), so a fresh install scans at once
and ``gonio library import`` costs seconds, not minutes.

The shipped file is only as good as its agreement with the code that would build it. Beside it,
``data/synthetic-basis.json`` records a fingerprint: a SHA-256 over the builder's parameters
(components, randomized-SVD settings, remap constant, library key and seed, file format) and
over the source of every module that builds the library and the basis
(:data:`SOURCE_MODULES`), comments and docstrings left out so that prose edits do not count.
At run time a shipped file whose fingerprint differs from the code's is not used (the basis is
built as before, slowly but right), and the unit test
``tests/unit/brdf/reconstruction/test_shipped.py`` fails and names the command that rebuilds
it::

    python -m gonio.brdf.reconstruction.shipped
"""

from __future__ import annotations

import argparse
import ast
import dataclasses
import functools
import hashlib
import importlib.util
import io
import json
import sys
import tokenize
from pathlib import Path
from typing import Any

import numpy as np

from gonio.brdf.reconstruction import basis as _basis

DATA_DIR = Path(__file__).resolve().parent / "data"
SHIPPED_FILE = DATA_DIR / "synthetic-basis.npz"
FINGERPRINT_FILE = DATA_DIR / "synthetic-basis.json"
REBUILD_COMMAND = "python -m gonio.brdf.reconstruction.shipped"
#: Components of the shipped synthetic basis: the default K plus the extra ones the fold-in of
#: measured tables starts from (96), so the default basis is derived from it.
SHIPPED_COMPONENTS = _basis.DEFAULT_COMPONENTS + _basis._FOLD_EXTRA
#: The modules whose code decides the shipped basis' numbers: the grid, the table container,
#: the analytic models, the library's recipes and tabulation, the basis builder.
SOURCE_MODULES: tuple[str, ...] = (
    "gonio.brdf.tables.geometry",
    "gonio.brdf.tables.table",
    "gonio.brdf.models.analytic",
    "gonio.brdf.materials.library",
    "gonio.brdf.reconstruction.basis",
)


class ShippedBasisError(RuntimeError):
    """The shipped basis and its fingerprint file disagree or cannot be read."""


def build_parameters() -> dict[str, Any]:
    """What the shipped basis is built with, beside the code (part of the fingerprint).

    Returns
    -------
    dict
        Components, randomized-SVD settings and remap constant of
        :func:`~gonio.brdf.reconstruction.basis.build_basis` (its defaults), the library's key,
        version and seed, and the basis file format.
    """
    import inspect

    from gonio.brdf.materials import library

    params = inspect.signature(_basis.build_basis).parameters
    defaults = {name: p.default for name, p in params.items()
                if p.default is not inspect.Parameter.empty and name != "progress"}
    return {
        "n_components": SHIPPED_COMPONENTS,
        "build_basis": defaults,
        "library_key": library.library_key(),
        "library_version": library.LIBRARY_VERSION,
        "library_seed": library.DEFAULT_SEED,
        "format": [_basis.FORMAT_NAME, _basis.FORMAT_VERSION],
    }


def _module_path(name: str) -> Path:
    spec = importlib.util.find_spec(name)
    if spec is None or spec.origin is None:
        raise ShippedBasisError(f"module {name} has no source file to fingerprint")
    return Path(spec.origin)


def code_text(source: str) -> str:
    """The text of Python ``source`` that decides what it computes.

    Comments (found by :mod:`tokenize`) and docstrings (the leading string of a module,
    class or function, found by :mod:`ast`) are cut out by their positions, trailing
    whitespace and blank lines dropped; everything else is kept as written. Working on the
    text, not on token types or an AST dump, keeps the result the same on every Python
    version, so an install on another Python still recognises the shipped basis as its own.

    Parameters
    ----------
    source : str
        A module's text.

    Returns
    -------
    str
        The remaining lines, newline-separated.
    """
    lines = source.splitlines()

    def char_col(line: int, byte_col: int) -> int:
        # ast counts columns in UTF-8 bytes, tokenize in characters.
        return len(lines[line - 1].encode()[:byte_col].decode(errors="ignore"))

    # (first line, first column, last line, end column) of every span to cut; lines 1-based.
    spans: list[tuple[int, int, int, int]] = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Module | ast.ClassDef | ast.FunctionDef | ast.AsyncFunctionDef):
            body = node.body
            doc = body[0] if body else None
            if isinstance(doc, ast.Expr) and isinstance(doc.value, ast.Constant) \
                    and isinstance(doc.value.value, str) and doc.end_lineno is not None \
                    and doc.end_col_offset is not None:
                spans.append((doc.lineno, char_col(doc.lineno, doc.col_offset),
                              doc.end_lineno, char_col(doc.end_lineno, doc.end_col_offset)))
    for tok in tokenize.generate_tokens(io.StringIO(source).readline):
        if tok.type == tokenize.COMMENT:
            spans.append((*tok.start, *tok.end))
    for l0, c0, l1, c1 in sorted(spans, reverse=True):
        head, tail = lines[l0 - 1][:c0], lines[l1 - 1][c1:]
        lines[l0 - 1:l1] = [head + tail]
    return "\n".join(ln.rstrip() for ln in lines if ln.strip())


@functools.cache
def fingerprint() -> str:
    """SHA-256 (hex) of :func:`build_parameters` and the code of :data:`SOURCE_MODULES`.

    Computed once per process (the code does not change under a running interpreter).
    """
    h = hashlib.sha256(json.dumps(build_parameters(), sort_keys=True).encode())
    for name in SOURCE_MODULES:
        h.update(f"\0{name}\0".encode())
        h.update(code_text(_module_path(name).read_text(encoding="utf-8")).encode())
    return h.hexdigest()


def recorded() -> dict[str, Any]:
    """The fingerprint file's content (``fingerprint``, ``sha256`` of the shipped file, ...).

    Raises
    ------
    ShippedBasisError
        The file is missing or not JSON.
    """
    try:
        data = json.loads(FINGERPRINT_FILE.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise ShippedBasisError(
            f"cannot read {FINGERPRINT_FILE.name} beside the shipped basis ({exc}); rebuild "
            f"both with `{REBUILD_COMMAND}`"
        ) from None
    if not isinstance(data, dict):
        raise ShippedBasisError(f"{FINGERPRINT_FILE.name} is not a JSON object; rebuild it")
    return data


def file_sha256(path: Path = SHIPPED_FILE) -> str:
    """SHA-256 (hex) of a file's bytes."""
    return hashlib.sha256(path.read_bytes()).hexdigest()


def is_current() -> bool:
    """Whether the shipped basis exists and was built by this code with these parameters."""
    if not SHIPPED_FILE.is_file():
        return False
    try:
        return recorded().get("fingerprint") == fingerprint()
    except (ShippedBasisError, OSError, ValueError, SyntaxError):
        # An install without readable module sources cannot vouch for the file: build instead.
        return False


def shipped_basis(n_components: int) -> _basis.Basis | None:
    """The shipped synthetic basis when it is current and has ``n_components``; else None.

    Returns
    -------
    Basis or None
        None for another K, a missing or stale file (the caller builds instead) or a file
        that does not load.
    """
    if n_components != SHIPPED_COMPONENTS or not is_current():
        return None
    try:
        return _basis.Basis.load(SHIPPED_FILE)
    except _basis.BasisError:
        return None


def rebuild(progress: bool = True) -> Path:
    """Build the synthetic basis from the library and write the shipped file and fingerprint.

    The library is tabulated into the user cache first when it is not there (about two
    minutes); the basis build itself takes a few seconds more.

    Returns
    -------
    Path
        :data:`SHIPPED_FILE`.
    """
    from gonio.brdf.materials import library

    tables = library.default_library(progress=progress)
    basis = _basis.build_basis(tables, SHIPPED_COMPONENTS, progress=progress)
    # No timing, machine-specific path or fingerprint in the file itself: the same numbers
    # give the same bytes, so a rebuild after a change that moves no number (a refactoring)
    # leaves the committed binary alone and only the fingerprint file changes.
    prov = {k: v for k, v in basis.provenance.items() if k not in ("build_seconds", "file")}
    prov["shipped"] = {"fingerprint_file": FINGERPRINT_FILE.name, "rebuild": REBUILD_COMMAND}
    DATA_DIR.mkdir(parents=True, exist_ok=True)
    dataclasses.replace(basis, provenance=prov).save(SHIPPED_FILE, dtype=np.float32)
    record = {
        "fingerprint": fingerprint(),
        "sha256": file_sha256(),
        "bytes": SHIPPED_FILE.stat().st_size,
        "parameters": build_parameters(),
        "modules": list(SOURCE_MODULES),
        "rebuild": REBUILD_COMMAND,
    }
    FINGERPRINT_FILE.write_text(json.dumps(record, indent=2, sort_keys=True) + "\n",
                                encoding="utf-8")
    return SHIPPED_FILE


def main(argv: list[str] | None = None) -> int:
    """``python -m gonio.brdf.reconstruction.shipped [--check]``: rebuild, or only check."""
    ap = argparse.ArgumentParser(
        prog="python -m gonio.brdf.reconstruction.shipped",
        description="Rebuild the shipped synthetic basis and its fingerprint (run after changing "
        "the library, the models or the basis builder), or --check whether it is current.")
    ap.add_argument("--check", action="store_true", help="only say whether it is current")
    args = ap.parse_args(argv)
    if args.check:
        ok = is_current()
        print(f"{SHIPPED_FILE.name}: " + ("current" if ok else
              f"stale or missing; rebuild it with `{REBUILD_COMMAND}`"))
        return 0 if ok else 1
    path = rebuild(progress=sys.stderr.isatty())
    print(f"wrote {path} ({path.stat().st_size / 1e6:.1f} MB) and {FINGERPRINT_FILE.name}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
