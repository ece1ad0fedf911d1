"""The ``gonio`` command.

Each sub-command lives in its own module of this package and exposes
``register(subparsers) -> None``, which adds its parser and sets ``func`` (a callable taking the
parsed namespace and returning an exit code). Add new modules to ``COMMAND_MODULES`` with the
names their ``register`` adds.

A command pays only for its own imports: ``gonio keys list`` imports ``keys_command`` alone
(:func:`build_parser`), and a command module imports at its top only what ``register`` needs
(argparse, a few constants); what its commands do imports inside the function that does it.
``gonio --help`` and a mistyped name still import every module, to list them all.
Measured figures: docs/architecture.md, "What a command imports".
"""

from __future__ import annotations

import argparse
import contextlib
import errno
import importlib
import math
import os
import signal
import sqlite3
import sys
from collections.abc import Callable, Iterable, Sequence

from gonio import __version__
from gonio.brdf.advice import AdvisedError

# The flag of each core setting an error may advise changing (gonio.brdf.advice).
CORE_SETTING_FLAGS = {
    "max_elevation_deg": "--max-elevation",
    "min_separation_deg": "--min-separation",
    "min_device_distance_deg": "--min-device-distance",
    "replace": "--replace",
    "cell_mix": "--render-mix",
}

COMMAND_MODULES: dict[str, tuple[str, ...]] = {
    "gonio.cli.brdf_commands": ("basis", "library", "simulate-scan", "reconstruct", "demo"),
    "gonio.cli.scan_commands": ("scan",),
    "gonio.cli.jobs_command": ("jobs",),
    "gonio.cli.sim_command": ("sim", "sim-place"),
    "gonio.cli.serve_command": ("serve",),
    "gonio.cli.design_command": ("design",),
    "gonio.cli.stage_command": ("stage",),
    "gonio.cli.rig_command": ("rig",),
    "gonio.cli.export_command": ("export",),
    "gonio.cli.keys_command": ("keys",),
    "gonio.cli.render_command": ("render",),
    "gonio.cli.colour_command": ("colour", "color", "colour-chart", "color-chart"),
}
"""Each command module, in the order ``gonio --help`` lists them, with the command names (and
aliases) its ``register`` adds (tests/unit/test_start_imports.py holds them to it)."""


class UsageError(Exception):
    """A user error the CLI reports as one line on stderr with exit code 2."""


def refuse_to_replace(out: str | os.PathLike[str] | None, overwrite: bool, undone: str,
                      flag: str = "-o") -> None:
    """Refuse an ``-o`` that names an existing file unless ``overwrite`` (``--overwrite``),
    before the command's work: a design fragment (a minute's search, the lab's mounting plan),
    a reconstructed table or a rendering was replaced without a word, where ``scan``,
    ``export`` and ``colour`` refuse. ``undone`` says what was not done ("nothing was
    designed"); ``flag`` is the option that named the file."""
    from pathlib import Path

    if out is None:
        return
    path = Path(out)
    if path.is_dir():
        raise UsageError(f"{flag} {path} is a folder; name the file to write ({undone})")
    if path.exists() and not overwrite:
        raise UsageError(f"{path} exists: {undone}; give {flag} another file, or --overwrite "
                         "to replace it")


class StoppedBySignal(KeyboardInterrupt):
    """A command stopped by SIGTERM or SIGHUP as Ctrl-C stops it: reported "interrupted", with
    the exit status a shell gives a process the signal ends (128 + its number: 143 for
    SIGTERM, 129 for SIGHUP), so ``timeout`` and service managers see which stop it was."""

    def __init__(self, signum: int) -> None:
        super().__init__(signum)
        self.signum = int(signum)


def _number(kind: type[float] | type[int], test: Callable[[float], bool], what: str
            ) -> Callable[[str], float]:
    def parse(text: str) -> float:
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}") from None
        if not (math.isfinite(value) and test(value)):
            raise argparse.ArgumentTypeError(f"expected {what}, got {text}")
        return value

    parse.__name__ = what  # argparse names the type in some messages
    return parse


positive_float = _number(float, lambda v: v > 0, "a finite number > 0")
"""``type=`` for flags like --time-scale and --threshold: finite and > 0."""
nonnegative_float = _number(float, lambda v: v >= 0, "a finite number >= 0")
finite_float = _number(float, lambda v: True, "a finite number")
positive_int = _number(int, lambda v: v >= 1, "a whole number >= 1")


def _describe_validation(exc: Exception) -> str:
    """One line per problem of a pydantic ``ValidationError``, named by field."""
    errors = getattr(exc, "errors", None)
    if errors is None:
        return str(exc)
    parts = []
    for err in errors():
        loc = ".".join(str(p) for p in err.get("loc", ())) or "value"
        # pydantic prefixes a validator's own sentence with "Value error, ": not the user's.
        msg = str(err.get("msg", "invalid")).removeprefix("Value error, ")
        parts.append(f"{loc}: {msg}")
    return "; ".join(parts)


def build_parser(argv: Sequence[str] | None = None) -> argparse.ArgumentParser:
    """The ``gonio`` parser, for parsing ``argv``.

    Parameters
    ----------
    argv : sequence of str, optional
        The arguments it will parse. When the first one names a command, only that command's
        module registers (its import is all the command pays for before it runs); for
        ``--version`` none does; otherwise (no command, ``--help``, a mistyped name) every
        module does, so the help and argparse's "invalid choice" list every command.
    """
    parser = argparse.ArgumentParser(
        prog="gonio",
        description="Fast anisotropic BRDF acquisition: design, scan, reconstruct, serve.",
    )
    parser.add_argument("--version", action="version", version=f"gonio {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    first = argv[0] if argv else None
    if first == "--version":
        modules: Iterable[str] = ()
    else:
        modules = [m for m, names in COMMAND_MODULES.items() if first in names] or COMMAND_MODULES
    for name in modules:
        importlib.import_module(name).register(sub)
    return parser


def _with_advice(message: object) -> str:
    """An error's words, with what to do about a damaged result file, whichever command read
    it (export, colour and reconstruct wrap the reader's error): as the daemon's answer for
    the same file says it."""
    from gonio.wording import DAMAGED, DAMAGED_ADVICE

    text = str(message)
    return f"{text}; {DAMAGED_ADVICE}" if DAMAGED in text else text


def main(argv: Sequence[str] | None = None) -> int:
    # Before the parser loads NumPy: BLAS on one thread (why: gonio.brdf.reconstruction.blas).
    from gonio.brdf.reconstruction.blas import prefer_one_thread

    prefer_one_thread()
    # pymodbus' own lines on the terminal ("Failed to connect ...", "Repeating....", raw frame
    # dumps) beside the driver's fault, which names the device and what to check.
    from gonio.logfilters import install_pymodbus

    install_pymodbus()
    argv = sys.argv[1:] if argv is None else list(argv)
    parser = build_parser(argv)
    args = parser.parse_args(argv)
    if getattr(args, "func", None) is None:
        parser.print_help()
        return 2
    try:
        code = int(args.func(args) or 0)
        sys.stdout.flush()  # a closed pipe shows up here, inside the handlers below
        return code
    except UsageError as exc:
        print(f"gonio {args.command}: error: {_with_advice(exc)}", file=sys.stderr)
        return 2
    except BrokenPipeError:
        # The reader went away (``gonio jobs show 2 | head``): not an error of ours, and
        # nothing more can be written. Point stdout at /dev/null so the interpreter's final
        # flush does not raise again.
        with contextlib.suppress(OSError):
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, sys.stdout.fileno())
        return 141  # 128 + SIGPIPE, what a shell reports for a process killed by it
    except _validation_error() as exc:
        print(f"gonio {args.command}: error: {_describe_validation(exc)}", file=sys.stderr)
        return 2
    except ValueError as exc:
        # Domain errors (bad table, plan, config ...) are ValueError subclasses with messages
        # written for the user; anything else is a bug and keeps its traceback. Core errors
        # that advise a setting name it as the core does; here it is the flag.
        message = exc.advise(CORE_SETTING_FLAGS) if isinstance(exc, AdvisedError) else exc
        print(f"gonio {args.command}: error: {_with_advice(message)}", file=sys.stderr)
        return 2
    except KeyboardInterrupt as exc:
        print("interrupted", file=sys.stderr)
        # 128 + the signal's number, as a shell reports a process the signal ended.
        return 128 + (exc.signum if isinstance(exc, StoppedBySignal) else signal.SIGINT)
    except sqlite3.Error as exc:
        # The job store cannot be opened or written (read-only or full disk, a foreign file).
        print(f"gonio {args.command}: error: job store: {exc}", file=sys.stderr)
        return 1
    except OSError as exc:
        # A file or directory the user named cannot be read or written: say which and why.
        print(f"gonio {args.command}: error: {_describe_os_error(exc)}", file=sys.stderr)
        return 1


class _NotRaised(Exception):
    """Matches nothing: what :func:`_validation_error` gives before pydantic is loaded."""


def _validation_error() -> type[Exception]:
    """pydantic's ``ValidationError`` if the command loaded pydantic, else :class:`_NotRaised`.

    Evaluated by ``main``'s ``except`` clause only when an exception arrives. A command that
    never loaded pydantic cannot have raised its error, and importing pydantic just to catch
    one would make every light command (``gonio keys``) pay for loading it.
    """
    pydantic = sys.modules.get("pydantic")
    return _NotRaised if pydantic is None else pydantic.ValidationError


def _describe_os_error(exc: OSError) -> str:
    what = exc.strerror or str(exc)
    where = exc.filename
    hint = {
        errno.ENOENT: "check that the directory exists",
        errno.EACCES: "check the permissions, or choose another location",
        errno.EROFS: "the file system is read-only; choose another location",
        errno.ENOSPC: "free some disk space",
        errno.EEXIST: "a file of that name is in the way of a directory",
        errno.ENOTDIR: "part of the path is a file, not a directory",
    }.get(exc.errno or 0, "")
    text = f"{where}: {what}" if where else what
    return f"{text}; {hint}" if hint else text


if __name__ == "__main__":
    raise SystemExit(main())
