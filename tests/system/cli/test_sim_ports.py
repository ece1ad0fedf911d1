"""The simulated rig's Modbus port can be chosen (shared lab machines with firewalls), and a
port in use is said in one line (issue 27, item 10)."""

from __future__ import annotations

import socket
import tomllib
from pathlib import Path

import pytest

from gonio.cli import main
from tests.system.daemon_proc import PROJECT_ROOT

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


def test_gonio_sim_replaces_its_own_config_but_not_a_labs(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The README's simulated session writes ``gonio sim -o rig.toml``, the name a lab gives
    its own rig config: that file was replaced without a word or a backup. Now a file an
    earlier ``gonio sim`` wrote is replaced (restarting the simulator), any other is kept and
    the refusal says how to replace it."""
    rig = tmp_path / "rig.toml"
    assert main(["sim", "--duration", "0", "-o", str(rig)]) == 0
    assert main(["sim", "--duration", "0", "-o", str(rig)]) == 0  # its own: replaced
    assert tomllib.loads(rig.read_text())["lights"]
    # Rewritten by `gonio rig apply-design`, it is still the simulator's (apply-design keeps
    # its first line), as apply-design's own note says: 'gonio sim --geometry ... -o' on it.
    geometry = tmp_path / "geometry.toml"
    assert main(["design", "--preset", "MA68", "--no-expected-error", "-o",
                 str(geometry)]) == 0
    assert main(["rig", "apply-design", str(geometry), str(rig)]) == 0
    assert rig.read_text().startswith("# Written by gonio sim")
    assert main(["sim", "--duration", "0", "--geometry", str(geometry), "-o", str(rig)]) == 0
    # A lab's own config copied over the name (the simulator's specimen recipe still beside
    # it) is the lab's: refused.
    (tmp_path / "rig.sim-specimen.json").write_text("{}")
    rig.write_text((PROJECT_ROOT / "deploy" / "rig.example.toml").read_text())
    capsys.readouterr()
    assert main(["sim", "--duration", "0", "-o", str(rig)]) == 2
    assert "was not written by gonio sim" in capsys.readouterr().err
    labs = tmp_path / "lab-rig.toml"
    text = (PROJECT_ROOT / "deploy" / "rig.example.toml").read_text()
    labs.write_text(text)
    capsys.readouterr()
    assert main(["sim", "--duration", "0", "-o", str(labs)]) == 2
    err = capsys.readouterr().err
    assert f"{labs} exists and was not written by gonio sim" in err, err
    assert "--overwrite" in err and "Traceback" not in err, err
    assert labs.read_text() == text
    assert main(["sim", "--duration", "0", "-o", str(labs), "--overwrite"]) == 0
    assert labs.read_text() != text
