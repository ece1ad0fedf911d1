"""`gonio serve` user errors: each gets one clear line and exit code 2."""

from __future__ import annotations

from pathlib import Path

import pytest

from gonio.cli import main


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["serve", "--port", "0"], "no rig config: give --rig"),
        (["serve", "--demo-scan"], "need --sim"),
        (["serve", "--sim", "--port", "70000"], "--port 70000"),
        (["serve", "--rig", "missing-rig.toml", "--port", "0"], "no such rig config file"),
        (["serve", "--sim", "--time-scale", "0", "--port", "0"], "--time-scale must be > 0"),
    ],
)
def test_serve_user_errors(argv: list[str], message: str, capsys: pytest.CaptureFixture[str],
                           tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("GONIO_API_KEYS", raising=False)
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("gonio serve: error:") and message in err


def test_serve_reports_bad_daemon_config(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    cfg = tmp_path / "daemon.toml"
    cfg.write_text("[server]\nprot = 1\n")
    assert main(["serve", "--config", str(cfg), "--sim"]) == 2
    assert "unknown key 'server.prot'" in capsys.readouterr().err
