"""``gonio keys new/list``: a key is shown once, the file keeps only what the daemon needs."""

from __future__ import annotations

import hashlib
import stat
from pathlib import Path

import pytest

from gonio.cli import main
from gonio.daemon import DaemonConfig, load_keyring


def test_new_key_is_printed_once_and_stored_as_its_digest(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    keys = tmp_path / "etc" / "api-keys"
    assert main(["keys", "new", "alice", "--keys-file", str(keys)]) == 0
    out = capsys.readouterr()
    key = out.out.strip()
    assert len(key) >= 32 and "only time it is shown" in out.err
    text = keys.read_text()
    assert key not in text
    # The stored form is the SHA-256 of the key (computed here with hashlib, not gonio).
    assert text == f"alice sha256:{hashlib.sha256(key.encode()).hexdigest()}\n"
    assert stat.S_IMODE(keys.stat().st_mode) == 0o600
    # The daemon accepts exactly that key under that name.
    cfg = DaemonConfig().with_overrides(auth__keys_file=str(keys))
    ring = load_keyring(cfg, environ={})
    assert ring.identify(key) == "alice"
    assert ring.identify(key[:-1] + ("A" if key[-1] != "A" else "B")) is None
    assert ring.identify(text.split()[1]) is None  # the digest itself is not a key

    assert main(["keys", "new", "bob", "--keys-file", str(keys)]) == 0
    bob = capsys.readouterr().out.strip()
    assert bob != key and len(keys.read_text().splitlines()) == 2
    ring = load_keyring(cfg, environ={"GONIO_API_KEYS": "ci:" + "x" * 20})
    assert (ring.identify(key), ring.identify(bob), ring.identify("x" * 20)) == (
        "alice", "bob", "ci")


def test_list_shows_names_never_keys(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                     monkeypatch: pytest.MonkeyPatch) -> None:
    keys = tmp_path / "api-keys"
    keys.write_text("old plainplainplainplain1234\n")
    keys.chmod(0o644)
    assert main(["keys", "new", "lab", "--keys-file", str(keys)]) == 0
    lab = capsys.readouterr().out.strip()
    monkeypatch.setenv("GONIO_API_KEYS", "ci:" + "y" * 20)
    assert main(["keys", "list", "--keys-file", str(keys)]) == 0
    out = capsys.readouterr()
    names = [line.split("\t")[0] for line in out.out.splitlines()]
    assert names == ["old", "lab", "ci"]
    assert "plainplain" not in out.out and lab not in out.out and "y" * 20 not in out.out
    assert "plain key (readable in the file" in out.out
    assert "readable by other users" in out.err


@pytest.mark.parametrize(
    ("argv", "words"),
    [
        (["new", "alice"], "already has a key named 'alice'"),
        (["new", "two words"], "use 1 to 64 letters"),
        (["new", "x#y"], "use 1 to 64 letters"),
    ],
)
def test_bad_key_requests_change_nothing(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], argv: list[str], words: str
) -> None:
    keys = tmp_path / "api-keys"
    assert main(["keys", "new", "alice", "--keys-file", str(keys)]) == 0
    before = keys.read_text()
    capsys.readouterr()
    assert main(["keys", *argv, "--keys-file", str(keys)]) == 2
    assert words in capsys.readouterr().err
    assert keys.read_text() == before


def test_keys_file_from_the_daemon_config(tmp_path: Path,
                                          capsys: pytest.CaptureFixture[str]) -> None:
    cfg = tmp_path / "daemon.toml"
    cfg.write_text('[auth]\nkeys_file = "keys/api-keys"\n')
    assert main(["keys", "new", "lab", "--config", str(cfg)]) == 0
    assert (tmp_path / "keys" / "api-keys").read_text().startswith("lab sha256:")
    cfg.write_text("[server]\nport = 8600\n")
    capsys.readouterr()
    assert main(["keys", "list", "--config", str(cfg)]) == 2
    assert "sets no [auth] keys_file" in capsys.readouterr().err
    assert main(["keys", "list", "--keys-file", str(tmp_path / "none")]) == 2
    assert "gonio keys new NAME" in capsys.readouterr().err


def test_new_keys_can_follow_api_key_on_a_command_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A printed key is pasted after ``--api-key``: argparse reads a leading '-' as an option,
    so no generated key may start with one (URL-safe base64 did, 1 time in 32)."""
    import argparse

    keys = tmp_path / "api-keys"
    parser = argparse.ArgumentParser()
    parser.add_argument("--api-key")
    for i in range(64):
        assert main(["keys", "new", f"k{i}", "--keys-file", str(keys)]) == 0
        key = capsys.readouterr().out.strip()
        assert parser.parse_args(["--api-key", key]).api_key == key
