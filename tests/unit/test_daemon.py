"""The daemon's own parts, in the test process: its config and API keys files (defaults,
relative paths, clear errors), what counts as a loopback bind, the console's job lines and the
HTTP settings it derives. The daemon running as a process: tests/system/api/."""

from __future__ import annotations

import logging
import os
import re
from pathlib import Path
from types import SimpleNamespace

import pytest

from gonio.apikeys import ApiKeyring
from gonio.daemon import (
    DEFAULT_HOST,
    DaemonConfig,
    DaemonConfigError,
    api_settings,
    is_loopback_host,
    job_event_line,
    load_daemon_config,
    load_keyring,
)

PROJECT = Path(__file__).resolve().parents[2]
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
    assert cfg.results.export_fits is True


def test_export_fits_from_the_file_and_the_command_line(tmp_path: Path) -> None:
    assert load_daemon_config(None).results.export_fits is True
    (tmp_path / "d.toml").write_text("[results]\nexport_fits = false\n")
    assert load_daemon_config(tmp_path / "d.toml").results.export_fits is False
    # `gonio serve --no-export-fits` overrides the file; an unset flag keeps it.
    on = load_daemon_config(None)
    assert on.with_overrides(results__export_fits=False).results.export_fits is False
    assert on.with_overrides(results__export_fits=None).results.export_fits is True


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
        ('[results]\nexport_fits = "later"\n', "results.export_fits"),
        ("[results]\nfit_exports = false\n", "unknown key 'results.fit_exports'"),
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


def test_a_malformed_keys_file_is_a_config_error_naming_the_line(tmp_path: Path) -> None:
    # The parser says what is wrong (tests/unit/test_apikeys.py); the daemon reports it as
    # its configuration error, like a missing file.
    (tmp_path / "api-keys").write_text(f"a {K1}\na {K2}\n")
    (tmp_path / "api-keys").chmod(0o600)
    (tmp_path / "d.toml").write_text('[auth]\nkeys_file = "api-keys"\n')
    with pytest.raises(DaemonConfigError, match="api-keys, line 2: key name 'a' is used twice"):
        load_keyring(load_daemon_config(tmp_path / "d.toml"), {})
    with pytest.raises(DaemonConfigError, match="GONIO_API_KEYS: key name 'x' is used twice"):
        load_keyring(load_daemon_config(None), {"GONIO_API_KEYS": f"x:{K1},x:{K2}"})


@pytest.mark.parametrize(("host", "loopback"), [
    ("127.0.0.1", True), ("127.0.0.2", True), ("127.255.255.254", True), ("localhost", True),
    ("::1", True), ("[::1]", True), ("::ffff:127.0.0.1", True),
    ("0.0.0.0", False), ("::", False), ("192.168.1.20", False), ("10.0.0.1", False),
    ("fe80::1%eth0", False), ("lab-pc.example.org", False), ("128.0.0.1", False),
])
def test_loopback_is_127_0_0_0_slash_8_and_ipv6_one(host: str, loopback: bool) -> None:
    # RFC 1122 3.2.1.3 (127.0.0.0/8) and RFC 4291 2.5.3 (::1): the loopback addresses.
    assert is_loopback_host(host) is loopback


def _row(**kw: object) -> SimpleNamespace:
    base: dict[str, object] = dict(id=7, kind="uniform", specimen="red tile", done_angles=3,
                                   total_angles=8, plan={"rotations": 8}, summary=None,
                                   result_path=None)
    base.update(kw)
    return SimpleNamespace(**base)


@pytest.mark.parametrize(("type_", "data", "row", "level", "line"), [
    ("state", {"from": "queued", "state": "running"}, _row(total_angles=0), logging.INFO,
     "job 7 (uniform, 'red tile') started: 8 stage angles"),
    # One angle is "1 stage angle", not "1 stage angles".
    ("state", {"from": "queued", "state": "running"},
     _row(total_angles=0, plan={"rotations": 1}), logging.INFO,
     "job 7 (uniform, 'red tile') started: 1 stage angle"),
    ("state", {"from": "paused", "state": "running"}, _row(), logging.INFO,
     "job 7 (uniform, 'red tile') resumed from paused (3 of 8 angles)"),
    ("state", {"state": "suspended", "reason": "stage: overload"}, _row(), logging.WARNING,
     "job 7 (uniform, 'red tile') suspended (3 of 8 angles): stage: overload"),
    ("state", {"state": "reconstructing"}, _row(done_angles=8), logging.INFO,
     "job 7 (uniform, 'red tile') measured 8 of 8 angles; reconstructing"),
    # A calibration reconstructs nothing (it said "reconstructing" too).
    ("state", {"state": "reconstructing"},
     _row(kind="calibration", specimen="white reference", done_angles=4, total_angles=4),
     logging.INFO, "job 7 (calibration, 'white reference') measured 4 of 4 angles; computing "
     "the calibration"),
    ("state", {"state": "completed"},
     _row(summary={"calibrated": True, "predicted_log_rmse": 0.2}, result_path="r/job-7.h5"),
     logging.INFO, "job 7 (uniform, 'red tile') completed, in 1/sr: predicted_log_rmse 0.200; "
                   "result r/job-7.h5"),
    ("state", {"state": "completed"}, _row(summary={}), logging.INFO,
     "job 7 (uniform, 'red tile') completed, UNCALIBRATED (sensor units): no error estimate"),
    ("state", {"state": "aborted", "reason": "by request"}, _row(), logging.INFO,
     "job 7 (uniform, 'red tile') aborted (3 of 8 angles): by request"),
    ("state", {"state": "failed"}, _row(), logging.ERROR,
     "job 7 (uniform, 'red tile') failed (3 of 8 angles)"),
    # A paused job is not resumed at start: it waits for the user, and the queue with it.
    ("recovered", {"state": "paused"}, _row(), logging.INFO,
     "job 7 (uniform, 'red tile') found paused at start (3 of 8 angles): stays paused until "
     "resumed (the page's resume, gonio jobs --daemon URL resume 7, or POST "
     "/api/v1/jobs/7/resume); queued jobs wait behind it"),
    ("recovered", {"state": "running"}, _row(), logging.INFO,
     "job 7 (uniform, 'red tile') found running at start (3 of 8 angles): resumes from its "
     "checkpoint"),
    ("recovered", {"state": "reconstructing"}, _row(done_angles=8), logging.INFO,
     "job 7 (uniform, 'red tile') found reconstructing at start (8 of 8 angles): its "
     "reconstruction starts again from the stored readings"),
    ("state", {"state": "queued"}, _row(), logging.DEBUG, None),
])
def test_the_console_line_of_each_job_event(type_: str, data: dict[str, object],
                                            row: SimpleNamespace, level: int,
                                            line: str | None) -> None:
    assert job_event_line(type_, data, row, service=None) == (level, line)


def test_a_finished_calibration_says_it_applies() -> None:
    service = SimpleNamespace(calibration=lambda: SimpleNamespace(source="job 7",
                                                                  pairs=[1, 2, 3]))
    level, line = job_event_line("state", {"state": "completed"}, _row(kind="calibration"),
                                 service)
    assert level == logging.INFO
    assert line == ("job 7 (calibration, 'red tile') completed: calibration applied (job 7, 3 "
                    "pairs): later scans are in 1/sr")


def test_a_calibration_of_one_pair_says_one_pair() -> None:
    service = SimpleNamespace(calibration=lambda: SimpleNamespace(source="job 7", pairs=[1]))
    _, line = job_event_line("state", {"state": "completed"}, _row(kind="calibration"),
                             service)
    assert line is not None and "(job 7, 1 pair): later scans" in line, line


def test_the_http_settings_follow_the_config(tmp_path: Path) -> None:
    cfg = DaemonConfig().with_overrides(paths__data_dir=str(tmp_path),
                                        limits__max_body_bytes=4096,
                                        auth__read_requires_key=True)
    ring = ApiKeyring({"lab": K1})
    settings = api_settings(cfg, ring)
    assert settings.access.keyring is ring and settings.access.read_requires_key
    assert settings.data_dir == tmp_path and settings.max_body_bytes == 4096


def test_the_config_module_knows_every_table_of_the_daemon_config() -> None:
    """gonio.config tells a daemon config from a rig config by its tables (it cannot import
    the daemon's model, a layer above): the list must stay the model's."""
    from gonio.config import DAEMON_TABLES
    from gonio.daemon import DaemonConfig

    assert set(DaemonConfig.model_fields) == DAEMON_TABLES


def test_a_rig_config_given_as_the_daemon_config_says_so() -> None:
    """``gonio serve --config rig.toml`` listed an "unknown key" line for each of the rig
    config's tables; the file is the other kind, and one line says so and where it goes."""
    with pytest.raises(DaemonConfigError) as exc:
        load_daemon_config(PROJECT / "deploy" / "rig.example.toml")
    text = str(exc.value)
    assert text.startswith("rig.example.toml: a rig config") and "not a daemon config" in text
    assert "--rig" in text and "rig_config" in text, text
    assert "unknown key" not in text and len(text.splitlines()) == 1, text


def test_a_number_or_a_switch_written_as_text_is_refused_in_the_daemon_config() -> None:
    """``port = "8600"`` was read as 8600 without a word, as in the rig config (whose sections
    refuse it since 2026-11-28); ``export_fits = "false"`` likewise as False."""
    from gonio.daemon import DaemonConfigError, _validate

    with pytest.raises(DaemonConfigError) as info:
        _validate({"server": {"port": "8600"}}, "daemon.toml")
    assert str(info.value) == ("daemon.toml: server.port: expected a number, got the text "
                               "'8600': write it without quotes"), info.value
    with pytest.raises(DaemonConfigError) as info:
        _validate({"results": {"export_fits": "false"}}, "daemon.toml")
    assert "expected true or false, got the text 'false'" in str(info.value), info.value
    assert _validate({"server": {"port": 8600}}, "daemon.toml").server.port == 8600
