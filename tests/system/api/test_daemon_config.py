"""Daemon config and API keys files: defaults, relative paths, and clear errors."""

from __future__ import annotations

import os
import re
from pathlib import Path

import pytest

from gonio.daemon import (
    DEFAULT_HOST,
    DaemonConfigError,
    load_daemon_config,
    load_keyring,
    parse_keys_env,
    parse_keys_file,
)

PROJECT = Path(__file__).resolve().parents[3]
K1 = "k" * 20
K2 = "q" * 24


def test_defaults_bind_loopback() -> None:
    cfg = load_daemon_config(None)
    assert cfg.server.host == DEFAULT_HOST == "127.0.0.1"
    assert cfg.auth.keys_file is None
    # No data directory configured: the rig's own (gonio scan's), settled with the rig.
    assert cfg.paths.data_dir is None


def test_without_a_data_dir_the_daemon_uses_the_rigs_own(tmp_path: Path) -> None:
    from gonio.config import load_rig_config
    from gonio.paths import scan_data_dir

    rig = load_rig_config(PROJECT / "deploy" / "rig.example.toml")
    assert load_daemon_config(None).for_rig(rig).paths.data_dir == scan_data_dir(rig)
    given = load_daemon_config(None).with_overrides(paths__data_dir=str(tmp_path))
    assert given.for_rig(rig).paths.data_dir == tmp_path


def test_example_config_loads() -> None:
    cfg = load_daemon_config(PROJECT / "deploy" / "daemon.example.toml")
    assert cfg.server.host == "127.0.0.1"
    assert cfg.paths.data_dir == Path("/var/lib/gonio")
    assert cfg.auth.keys_file == Path("/etc/gonio/api-keys")


def test_relative_paths_resolve_against_the_config_file(tmp_path: Path) -> None:
    (tmp_path / "d.toml").write_text('[auth]\nkeys_file = "keys"\n[paths]\ndata_dir = "data"\n')
    cfg = load_daemon_config(tmp_path / "d.toml")
    assert cfg.auth.keys_file == tmp_path / "keys"
    assert cfg.paths.data_dir == tmp_path / "data"


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("[server]\nprot = 1\n", "unknown key 'server.prot'"),
        ("[server]\nport = 70000\n", "server.port"),
        ("[server\n", "not valid TOML"),
        ("[limits]\nmax_body_bytes = 10\n", "limits.max_body_bytes"),
        ("[limits]\ndesign_time_limit_s = 0\n", "limits.design_time_limit_s"),
        ("[limits]\ndesign_time_limit_s = 3600\n", "limits.design_time_limit_s"),
    ],
)
def test_bad_config_names_the_key(tmp_path: Path, text: str, message: str) -> None:
    p = tmp_path / "daemon.toml"
    p.write_text(text)
    with pytest.raises(DaemonConfigError, match=message):
        load_daemon_config(p)


def test_missing_config_points_at_the_example(tmp_path: Path) -> None:
    with pytest.raises(DaemonConfigError, match=r"daemon\.example\.toml"):
        load_daemon_config(tmp_path / "nope.toml")


def test_overrides_replace_only_given_values() -> None:
    cfg = load_daemon_config(None).with_overrides(server__port=9999, server__host=None)
    assert cfg.server.port == 9999 and cfg.server.host == "127.0.0.1"
    with pytest.raises(DaemonConfigError, match=r"server\.port"):
        cfg.with_overrides(server__port=-1)


def test_keys_file_and_env_combine_and_errors_never_show_keys(tmp_path: Path) -> None:
    keys = tmp_path / "keys"
    keys.write_text(f"# lab keys\nalice {K1}\n\n")
    os.chmod(keys, 0o600)
    (tmp_path / "d.toml").write_text('[auth]\nkeys_file = "keys"\n')
    cfg = load_daemon_config(tmp_path / "d.toml")
    ring = load_keyring(cfg, {"GONIO_API_KEYS": f"bob:{K2}"})
    assert ring.identify(K1) == "alice" and ring.identify(K2) == "bob"

    with pytest.raises(DaemonConfigError, match="also in the keys file"):
        load_keyring(cfg, {"GONIO_API_KEYS": f"alice:{K2}"})
    keys.write_text(f"alice {K1} extra\n")
    with pytest.raises(DaemonConfigError, match="line 1") as info:
        load_keyring(cfg, {})
    assert K1 not in str(info.value)
    keys.write_text("alice short\n")
    short = re.escape("'alice' is 5 characters long; use at least 16")
    with pytest.raises(DaemonConfigError, match=short):
        load_keyring(cfg, {})


def test_missing_keys_file_says_what_to_do(tmp_path: Path) -> None:
    (tmp_path / "d.toml").write_text('[auth]\nkeys_file = "missing-keys"\n')
    with pytest.raises(DaemonConfigError, match="API keys file not found"):
        load_keyring(load_daemon_config(tmp_path / "d.toml"), {})


def test_parse_helpers() -> None:
    assert parse_keys_file(f"a {K1}\nb {K2} # comment\n", "f") == {"a": K1, "b": K2}
    with pytest.raises(DaemonConfigError, match="used twice"):
        parse_keys_file(f"a {K1}\na {K2}\n", "f")
    assert parse_keys_env(f"{K1}, x:{K2}") == {"env-1": K1, "x": K2}
