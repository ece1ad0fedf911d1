"""The ``gonio`` command.

Each sub-command lives in its own module of this package and exposes
``register(subparsers) -> None``, which adds its parser and sets ``func`` (a callable taking the
parsed namespace and returning an exit code). Add new modules to ``COMMAND_MODULES``.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Sequence

from gonio import __version__

COMMAND_MODULES: tuple[str, ...] = (
    "gonio.cli.brdf_commands",
    "gonio.cli.scan_commands",
    "gonio.cli.sim_command",
    "gonio.cli.serve_command",
    "gonio.cli.design_command",
    "gonio.cli.stage_command",
    "gonio.cli.rig_command",
    "gonio.cli.export_command",
    "gonio.cli.keys_command",
    "gonio.cli.render_command",
)


class UsageError(Exception):
    """A user error the CLI reports as one line on stderr with exit code 2."""


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="gonio",
        description="Fast anisotropic BRDF acquisition: design, scan, reconstruct, serve.",
    )
    parser.add_argument("--version", action="version", version=f"gonio {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMAND_MODULES:
        importlib.import_module(name).register(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if getattr(args, "func", None) is None:
        parser.print_help()
        return 2
    try:
        return int(args.func(args) or 0)
    except UsageError as exc:
        print(f"gonio {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except ValueError as exc:
        # Domain errors (bad table, plan, config ...) are ValueError subclasses with messages
        # written for the user; anything else is a bug and keeps its traceback.
        print(f"gonio {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    raise SystemExit(main())
