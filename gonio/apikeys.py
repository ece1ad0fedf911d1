"""API keys as the daemon keeps them: the stored digest, the keys file, the keyring.

One job: what a key is and where it is written down, without the HTTP layer. ``gonio keys``
(which writes and lists keys), the daemon config (which loads them) and the API's access
checks (:mod:`gonio.api.auth`) all import this module; it imports only the standard library,
so managing keys does not load FastAPI.

Keys are held only as SHA-256 digests and compared with :func:`hmac.compare_digest` against
*every* configured digest without stopping at the first match, so the time a check takes does not
tell an attacker how many characters were right, nor which key matched. A key is known to the
rest of the daemon (logs, events) only by its name, never by its value.

Keys come from a keys file (one ``name key`` per line, :func:`parse_keys_file`) and from the
environment variable :data:`KEYS_ENV` (``name:key`` entries separated by commas,
:func:`parse_keys_env`).
"""

from __future__ import annotations

import hashlib
import hmac
import re
from collections.abc import Mapping

MIN_KEY_LENGTH = 16
"""Shorter keys are refused at start-up: a lab network is not a trusted network."""

KEYS_ENV = "GONIO_API_KEYS"
"""Environment variable with more keys: ``name:key`` entries separated by commas."""

DIGEST_PREFIX = "sha256:"
"""A keys-file entry ``name sha256:<64 hex digits>`` is a key stored as its digest only."""
_STORED_DIGEST = re.compile(r"^sha256:([0-9a-f]{64})$")


class KeyringError(ValueError):
    """A configured API key is unusable; the message names it and says how to fix it."""


def _digest(key: str) -> bytes:
    return hashlib.sha256(key.encode("utf-8")).digest()


def stored_form(key: str) -> str:
    """What a keys file keeps of ``key``: ``sha256:<hex digest>`` (all the daemon needs)."""
    return DIGEST_PREFIX + _digest(key).hex()


def is_stored_digest(value: str) -> bool:
    """True when a keys-file value is a digest (:func:`stored_form`), not the key itself."""
    return _STORED_DIGEST.match(value) is not None


def parse_keys_file(text: str, source: str) -> dict[str, str]:
    """Parse a keys file: one ``name key`` per line; blank lines and ``#`` comments ignored.

    Parameters
    ----------
    text : str
        The file's contents.
    source : str
        What to call the file in messages (its path).

    Returns
    -------
    dict of str to str
        Key name to key value or stored digest, in file order.

    Raises
    ------
    KeyringError
        A line does not have exactly two fields, or a name repeats. The message gives the line
        number but never the key itself.
    """
    keys: dict[str, str] = {}
    for n, raw in enumerate(text.splitlines(), start=1):
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        fields = line.split()
        if len(fields) != 2:
            raise KeyringError(
                f"{source}, line {n}: expected 'name key' (two fields separated by spaces), "
                f"found {len(fields)} field(s)"
            )
        name, key = fields
        if name in keys:
            raise KeyringError(f"{source}, line {n}: key name {name!r} is used twice")
        keys[name] = key
    return keys


def parse_keys_env(value: str) -> dict[str, str]:
    """Parse :data:`KEYS_ENV`: comma-separated ``name:key`` entries (a bare key is ``env-N``).

    Raises
    ------
    KeyringError
        A name repeats.
    """
    keys: dict[str, str] = {}
    for n, entry in enumerate((e.strip() for e in value.split(",")), start=1):
        if not entry:
            continue
        name, sep, key = entry.partition(":")
        if not sep:
            name, key = f"env-{n}", entry
        if name in keys:
            raise KeyringError(f"{KEYS_ENV}: key name {name!r} is used twice")
        keys[name] = key
    return keys


class ApiKeyring:
    """The set of accepted API keys, by name.

    Parameters
    ----------
    keys : mapping of str to str
        Key name (shown in logs and events, e.g. ``"alice"``) to key value, or to its stored
        digest ``sha256:<64 hex digits>`` (:func:`stored_form`, what ``gonio keys new`` writes).

    Raises
    ------
    KeyringError
        A key is shorter than :data:`MIN_KEY_LENGTH` characters or contains whitespace.
    """

    def __init__(self, keys: Mapping[str, str]) -> None:
        digests: list[tuple[str, bytes]] = []
        for name, key in keys.items():
            stored = _STORED_DIGEST.match(key)
            if stored is not None:
                digests.append((name, bytes.fromhex(stored.group(1))))
                continue
            if len(key) < MIN_KEY_LENGTH:
                raise KeyringError(
                    f"API key {name!r} is {len(key)} characters long; use at least "
                    f"{MIN_KEY_LENGTH} (generate one with: python -c "
                    "'import secrets; print(secrets.token_hex(32))')"
                )
            if any(c.isspace() for c in key):
                raise KeyringError(f"API key {name!r} contains whitespace; keys are single tokens")
            digests.append((name, _digest(key)))
        self._digests = tuple(digests)

    def __len__(self) -> int:
        return len(self._digests)

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(n for n, _ in self._digests)

    def identify(self, presented: str | None) -> str | None:
        """Name of the key ``presented`` matches, or None.

        Runs the same comparisons whatever the input, so timing does not leak which key (or how
        much of one) matched.
        """
        if presented is None:
            return None
        candidate = _digest(presented)
        found: str | None = None
        for name, digest in self._digests:
            if hmac.compare_digest(candidate, digest) and found is None:
                found = name
        return found
