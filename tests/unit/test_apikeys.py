"""API keys: the stored digest, the keys file and environment formats, the keyring."""

from __future__ import annotations

import hashlib

import pytest

from gonio.apikeys import (
    ApiKeyring,
    KeyringError,
    is_stored_digest,
    parse_keys_env,
    parse_keys_file,
    stored_form,
)

ALICE = "a" * 16
BOB = "b0b-" + "x" * 28


def test_the_stored_form_is_the_sha256_of_the_key() -> None:
    hexdigest = hashlib.sha256(ALICE.encode()).hexdigest()
    assert stored_form(ALICE) == "sha256:" + hexdigest
    assert is_stored_digest(stored_form(ALICE))
    assert not is_stored_digest(ALICE)
    assert not is_stored_digest("sha256:" + hexdigest.upper())  # lower-case hex only
    assert not is_stored_digest("sha256:" + hexdigest[:-1])


def test_keys_are_known_by_name_whether_given_plain_or_as_digest() -> None:
    ring = ApiKeyring({"alice": ALICE, "bob": stored_form(BOB)})
    assert len(ring) == 2 and ring.names == ("alice", "bob")
    assert ring.identify(ALICE) == "alice"
    assert ring.identify(BOB) == "bob"
    assert ring.identify(stored_form(BOB)) is None  # the digest is not the key
    assert ring.identify(ALICE[:-1]) is None
    assert ring.identify(None) is None


def test_the_first_name_wins_when_two_names_share_a_key() -> None:
    assert ApiKeyring({"first": ALICE, "second": ALICE}).identify(ALICE) == "first"


@pytest.mark.parametrize(("key", "message"), [
    ("short", "API key 'lab' is 5 characters long; use at least 16"),
    ("a" * 10 + " " + "b" * 10, "API key 'lab' contains whitespace; keys are single tokens"),
])
def test_an_unusable_key_is_refused_with_its_name(key: str, message: str) -> None:
    with pytest.raises(KeyringError, match=message):
        ApiKeyring({"lab": key})


def test_keys_file_lines_are_name_and_key_comments_and_blank_lines_ignored() -> None:
    text = f"# lab keys\nalice {ALICE}\n\nbob {stored_form(BOB)}  # the CI runner\n"
    assert parse_keys_file(text, "api-keys") == {"alice": ALICE, "bob": stored_form(BOB)}


@pytest.mark.parametrize(("text", "message"), [
    (f"alice {ALICE}\nbob\n", "api-keys, line 2: expected 'name key'.*found 1 field"),
    (f"alice {ALICE} extra\n", "api-keys, line 1: expected 'name key'.*found 3 field"),
    (f"alice {ALICE}\nalice {BOB}\n", "api-keys, line 2: key name 'alice' is used twice"),
])
def test_a_bad_keys_file_line_is_named_without_its_key(text: str, message: str) -> None:
    with pytest.raises(KeyringError, match=message) as caught:
        parse_keys_file(text, "api-keys")
    assert BOB not in str(caught.value) and ALICE not in str(caught.value)


def test_keys_from_the_environment_are_named_or_numbered() -> None:
    assert parse_keys_env("") == {}
    assert parse_keys_env(f" ci:{BOB} , {ALICE},") == {"ci": BOB, "env-2": ALICE}
    with pytest.raises(KeyringError, match="GONIO_API_KEYS: key name 'ci' is used twice"):
        parse_keys_env(f"ci:{BOB},ci:{ALICE}")
