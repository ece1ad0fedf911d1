"""``gonio keys``: create and list the daemon's API keys.

``gonio keys new NAME --keys-file FILE`` makes a random key, appends ``NAME sha256:<digest>``
to the keys file (created with mode 600) and prints the key once: the file keeps only its
SHA-256 digest, which is all the daemon needs to check it, so reading the file does not give a
key away. ``gonio keys list`` shows the names (never a key). A running daemon reads its keys at
start-up: restart it after adding one.

Keys are written and read with :mod:`gonio.apikeys` alone, so these commands do not load the
HTTP stack; only ``--config`` loads the daemon config's reader.
"""

from __future__ import annotations

import argparse
import os
import re
import secrets
import stat
import sys
from pathlib import Path
from typing import Any

from gonio.cli import UsageError

NAME = re.compile(r"^[A-Za-z0-9_.@-]{1,64}$")


def register(subparsers: Any) -> None:
    """Add the ``keys`` sub-command."""
    p = subparsers.add_parser("keys", help="create or list the daemon's API keys",
                              description=__doc__.split("\n\n")[1].replace("\n", " ")
                              if __doc__ else None)
    sub = p.add_subparsers(dest="keys_command", metavar="ACTION", required=True)
    new = sub.add_parser("new", help="create a key, print it once, store its digest")
    new.add_argument("name", help="who or what uses it (shown in logs and events)")
    lst = sub.add_parser("list", help="names of the configured keys (never the keys)")
    for q in (new, lst):
        # Not required by argparse: its "one of the arguments ... is required" does not say
        # which file is meant; _keys_file does.
        src = q.add_mutually_exclusive_group()
        src.add_argument("--keys-file", type=Path, metavar="FILE",
                         help="the keys file (e.g. /etc/gonio/api-keys)")
        src.add_argument("--config", type=Path, metavar="DAEMON_TOML",
                         help="a daemon config: use its [auth] keys_file")
    new.set_defaults(func=_new)
    lst.set_defaults(func=_list)


def _keys_file(args: argparse.Namespace) -> Path:
    if args.keys_file is not None:
        return Path(args.keys_file)
    if args.config is None:
        raise UsageError(f"which keys file? e.g. 'gonio keys {args.keys_command} "
                         + (f"{args.name} " if args.keys_command == "new" else "")
                         + "--keys-file api-keys' (the file 'gonio serve --keys-file' reads, "
                         "/etc/gonio/api-keys as a service), or --config daemon.toml to use "
                         "its [auth] keys_file")
    from gonio.daemon import DaemonConfigError, load_daemon_config

    try:
        path = load_daemon_config(args.config).auth.keys_file
    except DaemonConfigError as exc:
        raise UsageError(str(exc)) from None
    if path is None:
        raise UsageError(f"{args.config} sets no [auth] keys_file; add one (e.g. keys_file = "
                         "\"api-keys\") or give --keys-file")
    return path


def _read(path: Path) -> dict[str, str]:
    from gonio.apikeys import KeyringError, parse_keys_file

    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        return {}
    except OSError as exc:
        raise UsageError(f"{path}: cannot read the keys file: {exc.strerror}") from None
    try:
        return parse_keys_file(text, str(path))
    except KeyringError as exc:
        raise UsageError(str(exc)) from None


def _new(args: argparse.Namespace) -> int:
    from gonio.apikeys import stored_form

    if not NAME.match(args.name):
        raise UsageError(f"key name {args.name!r}: use 1 to 64 letters, digits or _.@- "
                         "(it appears in logs and events)")
    path = _keys_file(args)
    if args.name in _read(path):
        raise UsageError(f"{path} already has a key named {args.name!r}; choose another name, "
                         "or delete its line first to replace it")
    # Hex, never URL-safe base64: a key that starts with '-' is read as an option when it is
    # pasted after --api-key on a command line.
    key = secrets.token_hex(32)
    path.parent.mkdir(parents=True, exist_ok=True)
    # O_APPEND: an existing file keeps every line it had; a new one is private from the start.
    fd = os.open(path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o600)
    with os.fdopen(fd, "a", encoding="utf-8") as f:
        if f.tell() > 0 and not path.read_bytes().endswith(b"\n"):
            f.write("\n")
        f.write(f"{args.name} {stored_form(key)}\n")
    print(key)
    print(f"added key {args.name!r} to {path}; this is the only time it is shown (the file "
          "keeps its SHA-256 digest only). Send it as the X-API-Key header, or set "
          "GONIO_API_KEY for gonio stage/scan --daemon; restart the daemon to load it.",
          file=sys.stderr)
    return 0


def _list(args: argparse.Namespace) -> int:
    from gonio.apikeys import KEYS_ENV, KeyringError, is_stored_digest, parse_keys_env

    path = _keys_file(args)
    if not path.exists():
        raise UsageError(f"{path} does not exist; create a key with: gonio keys new NAME "
                         f"--keys-file {path}")
    keys = _read(path)
    for name, value in keys.items():
        kind = "digest" if is_stored_digest(value) else (
            "plain key (readable in the file; replace it with gonio keys new)")
        print(f"{name}\t{path}\t{kind}")
    try:
        env = parse_keys_env(os.environ.get(KEYS_ENV, ""))
    except KeyringError as exc:
        raise UsageError(str(exc)) from None
    for name in env:
        print(f"{name}\t${KEYS_ENV}\tplain key")
    if path.stat().st_mode & (stat.S_IRGRP | stat.S_IROTH):
        print(f"warning: {path} is readable by other users; chmod 600 it", file=sys.stderr)
    if not keys and not env:
        print(f"no keys in {path}: the daemon is read-only", file=sys.stderr)
    return 0
