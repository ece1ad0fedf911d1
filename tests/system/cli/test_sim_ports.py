"""The simulated rig's Modbus port can be chosen (shared lab machines with firewalls), and a
port in use is said in one line (issue 27, item 10)."""

from __future__ import annotations

import socket
import tomllib
from pathlib import Path

import pytest

from gonio.cli import main

pytestmark = pytest.mark.system


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def test_gonio_sim_listens_on_the_chosen_modbus_port(tmp_path: Path) -> None:
    port = _free_port()
    rig = tmp_path / "rig.toml"
    assert main(["sim", "--modbus-port", str(port), "--duration", "0", "-o", str(rig)]) == 0
    cfg = tomllib.loads(rig.read_text())
    ports = {d["modbus"]["port"] for d in [*cfg["lights"], *cfg["sensors"]]}
    assert ports == {port}


def test_a_modbus_port_in_use_is_refused_in_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = int(busy.getsockname()[1])
        code = main(["scan", "--sim", "--modbus-port", str(port), "--dry-run",
                     "-o", str(tmp_path / "x.h5")])
    assert code == 2
    err = capsys.readouterr().err
    assert "cannot start the simulated rig" in err and f"127.0.0.1:{port}" in err, err
    assert "Traceback" not in err
    assert main(["sim", "--modbus-port", "70000", "--duration", "0"]) == 2
    assert "use 1 to 65535" in capsys.readouterr().err
