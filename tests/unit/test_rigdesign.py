"""Design fragments: written as [[tables]], merged into rig configs, read as pairs files."""

from __future__ import annotations

import tomllib
from pathlib import Path

import numpy as np
import pytest

from gonio.brdf.tables import geometry as geo
from gonio.cli import main
from gonio.cli.brdf_commands import read_pairs
from gonio.config import ConfigError, load_rig_config
from gonio.rigdesign import dump_fragment, load_fragment

EXAMPLE = Path(__file__).resolve().parents[2] / "deploy" / "rig.example.toml"

FRAGMENT = {
    "pairs": [{"light": "L1", "sensor": "S1"}, {"light": "L3", "sensor": "S3"}],
    "lights": [{"name": "L1", "theta_deg": 35.0, "phi_deg": 10.0},
               {"name": "L3", "theta_deg": 50.0, "phi_deg": 100.0}],
    "sensors": [{"name": "S1", "theta_deg": 25.0, "phi_deg": 200.0},
                {"name": "S3", "theta_deg": 15.0, "phi_deg": 300.0}],
}


def test_fragment_is_written_as_tables_that_append_to_a_rig_config(tmp_path: Path) -> None:
    text = dump_fragment(FRAGMENT, "a header\nsecond line")
    assert text.startswith("# a header\n# second line\n")
    assert text.count("[[lights]]") == 2 and text.count("[[pairs]]") == 2
    assert "lights = [" not in text  # no inline arrays: those cannot be extended later
    # The rig example without its devices plus the fragment is one valid TOML document with
    # the fragment's devices (what "merge it into a rig config" means at the text level).
    head = EXAMPLE.read_text().split("[[lights]]")[0].replace('pairs = "all"', "")
    data = tomllib.loads(head + "\n" + text)
    assert [d["name"] for d in data["lights"]] == ["L1", "L3"]
    assert data["pairs"][1] == {"light": "L3", "sensor": "S3"}


def test_apply_design_moves_known_devices_and_adds_new_ones(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    rig = tmp_path / "rig.toml"
    rig.write_text(EXAMPLE.read_text())
    geometry = tmp_path / "geometry.toml"
    geometry.write_text(dump_fragment(FRAGMENT))
    assert main(["rig", "apply-design", str(geometry), str(rig)]) == 0
    out = capsys.readouterr().out
    assert "L3: new light, hardware copied from L2 with device_id 3 on 192.168.10.20:502" in out
    assert "L2: lights the design does not use" in out
    assert (tmp_path / "rig.toml.bak").read_text() == EXAMPLE.read_text()
    cfg = load_rig_config(rig)
    assert [(p.light, p.sensor) for p in cfg.pair_list()] == [("L1", "S1"), ("L3", "S3")]
    l1 = cfg.light("L1")
    assert (l1.theta_deg, l1.phi_deg) == (35.0, 10.0)
    assert l1.modbus.host == "192.168.10.20" and l1.modbus.device_id == 1  # hardware kept
    s3 = cfg.sensor("S3")
    assert (s3.theta_deg, s3.phi_deg, s3.modbus.device_id) == (15.0, 300.0, 3)
    assert s3.channels == ["R", "G", "B"]
    # Applying the same design again changes nothing.
    before = rig.read_text()
    again = tmp_path / "b.toml"
    assert main(["rig", "apply-design", str(geometry), str(rig), "-o", str(again)]) == 0
    assert again.read_text() == before


def test_apply_design_keeps_a_backup_when_o_names_the_rig_config_itself(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """'-o' spelled differently (absolute path) but the same file is still an in-place edit."""
    monkeypatch.chdir(tmp_path)
    Path("rig.toml").write_text(EXAMPLE.read_text())
    Path("geometry.toml").write_text(dump_fragment(FRAGMENT))
    assert main(["rig", "apply-design", "geometry.toml", "rig.toml",
                 "-o", str(tmp_path / "rig.toml")]) == 0
    assert "previous version in rig.toml.bak" in capsys.readouterr().out
    assert Path("rig.toml.bak").read_text() == EXAMPLE.read_text()
    assert load_rig_config("rig.toml").light("L1").theta_deg == 35.0


def test_apply_design_drops_calibration_factors_of_moved_pairs(tmp_path: Path,
                                                               capsys: pytest.CaptureFixture[str]
                                                               ) -> None:
    rig = tmp_path / "rig.toml"
    rig.write_text(EXAMPLE.read_text() + '\n[[calibration.factors]]\nlight = "L1"\n'
                   'sensor = "S1"\nfactor = [1.0, 1.0, 1.0]\n')
    geometry = tmp_path / "g.toml"
    geometry.write_text(dump_fragment(FRAGMENT))
    assert main(["rig", "apply-design", str(geometry), str(rig)]) == 0
    assert "dropped 1 calibration factor" in capsys.readouterr().out
    cal = load_rig_config(rig).calibration
    assert cal is not None and cal.factors == []


@pytest.mark.parametrize(
    ("design_text", "match"),
    [
        ('[[lights]]\nname = "L1"\ntheta_deg = 95.0\nphi_deg = 0.0\n', "theta_deg"),
        ("lights = 3\n", "a design fragment has [[lights]]"),
        ('[[lights]]\nname = "L1"\ntheta_deg = 5.0\nphi_deg = 0.0\n[[sensors]]\nname = "S1"\n'
         'theta_deg = 5.0\nphi_deg = 0.0\n[[pairs]]\nlight = "L9"\nsensor = "S1"\n',
         "no light named 'L9'"),
        ("not toml = = 3", "not valid TOML"),
    ],
)
def test_apply_design_refuses_a_bad_design_and_leaves_the_rig_alone(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], design_text: str, match: str
) -> None:
    rig = tmp_path / "rig.toml"
    rig.write_text(EXAMPLE.read_text())
    geometry = tmp_path / "g.toml"
    geometry.write_text(design_text)
    assert main(["rig", "apply-design", str(geometry), str(rig)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("gonio rig: error:") and match in err
    assert rig.read_text() == EXAMPLE.read_text()
    assert not (tmp_path / "rig.toml.bak").exists()


def test_apply_design_needs_a_rig_with_devices(tmp_path: Path,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    rig = tmp_path / "rig.toml"
    rig.write_text('[rig]\nname = "x"\n')
    geometry = tmp_path / "g.toml"
    geometry.write_text(dump_fragment(FRAGMENT))
    assert main(["rig", "apply-design", str(geometry), str(rig)]) == 2
    assert "has no [[lights]] entries" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("rig_text", "match"),
    [
        (None, "rig.toml: no such rig config file; start from deploy/rig.example.toml"),
        ("[rig\nname = 3\n", "rig.toml: not valid TOML"),
        (b"\xff\xfe[rig]", "rig.toml: not a text file"),
    ],
)
def test_apply_design_names_an_unreadable_rig_config_and_writes_nothing(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], rig_text: str | bytes | None, match: str
) -> None:
    rig = tmp_path / "rig.toml"
    if isinstance(rig_text, bytes):
        rig.write_bytes(rig_text)
    elif rig_text is not None:
        rig.write_text(rig_text)
    before = rig.read_bytes() if rig.exists() else None
    geometry = tmp_path / "g.toml"
    geometry.write_text(dump_fragment(FRAGMENT))
    assert main(["rig", "apply-design", str(geometry), str(rig)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("gonio rig: error:") and match in err
    assert "Traceback" not in err
    assert (rig.read_bytes() if rig.exists() else None) == before
    assert not (tmp_path / "rig.toml.bak").exists()


def test_a_design_fragment_given_as_the_rig_config_says_so_in_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Swapped apply-design arguments, or --rig geometry.toml: say what the file is."""
    rig = tmp_path / "rig.toml"
    rig.write_text(EXAMPLE.read_text())
    geometry = tmp_path / "geometry.toml"
    geometry.write_text(dump_fragment(FRAGMENT))
    before = geometry.read_text()
    assert main(["rig", "apply-design", str(rig), str(geometry)]) == 2
    err = capsys.readouterr().err
    assert "geometry.toml: a design fragment" in err and "gonio rig apply-design" in err
    assert "required key is missing" not in err and len(err.splitlines()) <= 3
    assert geometry.read_text() == before and not (tmp_path / "geometry.toml.bak").exists()
    with pytest.raises(ConfigError, match=r"not a rig config: it has no \[rig\] or \[stage\]"):
        load_rig_config(geometry)
    load_rig_config(rig)  # a real rig config still loads


def test_pairs_file_reads_a_design_fragment_and_a_rig_config(tmp_path: Path) -> None:
    geometry = tmp_path / "geometry.toml"
    geometry.write_text(dump_fragment(FRAGMENT))
    cells, ph = read_pairs(geometry)
    # Independently: the half/difference angles of each pair's two lab directions.
    li = np.deg2rad([[35.0, 10.0], [50.0, 100.0]])
    se = np.deg2rad([[25.0, 200.0], [15.0, 300.0]])
    th, ph_expected, td, pd = geo.directions_to_half_diff(
        geo.spherical_to_direction(li[:, 0], li[:, 1]),
        geo.spherical_to_direction(se[:, 0], se[:, 1]))
    np.testing.assert_allclose(cells[:, 0], th, atol=1e-9)
    np.testing.assert_allclose(cells[:, 1], td, atol=1e-9)
    np.testing.assert_allclose(np.cos(2 * cells[:, 2]), np.cos(2 * pd), atol=1e-9)
    np.testing.assert_allclose(np.cos(ph), np.cos(ph_expected), atol=1e-9)
    # A rig config names its pairs the same way ("all" = every light with every sensor).
    cells_rig, _ = read_pairs(EXAMPLE)
    assert cells_rig.shape == (4, 3)
    assert load_fragment(EXAMPLE).pair_names() == [("L1", "S1"), ("L1", "S2"), ("L2", "S1"),
                                                   ("L2", "S2")]


def test_simulate_scan_takes_the_file_gonio_design_writes(tmp_path: Path,
                                                          capsys: pytest.CaptureFixture[str]
                                                          ) -> None:
    from gonio.brdf.models.analytic import Lambert, tabulate
    from gonio.brdf.reconstruction.samples import Samples

    table = tabulate(Lambert((0.3,), channels=("Y",), name="grey")).save(tmp_path / "grey.npz")
    geometry = tmp_path / "geometry.toml"
    geometry.write_text(dump_fragment(FRAGMENT, "from gonio design"))
    out = tmp_path / "samples.npz"
    assert main(["simulate-scan", "--table", str(table), "--pairs", str(geometry), "-r", "4",
                 "--noise", "0", "-o", str(out)]) == 0
    s = Samples.load(out)
    assert s.values.shape == (2, 4, 1)
    np.testing.assert_allclose(s.values, 0.3 / np.pi, rtol=1e-3)  # a Lambertian everywhere


def test_a_missing_or_binary_design_file_is_named_with_what_to_do(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"g\.toml: no such design file; start from the file "
                                          r"'gonio design -o' writes"):
        load_fragment(tmp_path / "g.toml")
    (tmp_path / "g.toml").write_bytes(b"\x89PNG\r\n")
    with pytest.raises(ConfigError, match=r"g\.toml: not a text file"):
        load_fragment(tmp_path / "g.toml")


def test_apply_design_on_a_gonio_sim_rig_config_says_to_restart_the_simulator(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # The README's real-rig session run against `gonio sim -o rig.toml`: apply-design added
    # devices with the next free ids, which the running simulator does not have, and the scan
    # failed on the first of them. The README's own substitution is `gonio sim --geometry`.
    from gonio.cli.sim_session import sim_specimen_path

    rig = tmp_path / "rig.toml"
    rig.write_text(EXAMPLE.read_text())
    geometry = tmp_path / "geometry.toml"
    geometry.write_text(dump_fragment(FRAGMENT))
    assert main(["rig", "apply-design", str(geometry), str(rig), "-o",
                 str(tmp_path / "real.toml")]) == 0
    assert "gonio sim" not in capsys.readouterr().out  # a real rig's config: no such note
    sim_specimen_path(rig).write_text("{}")  # what `gonio sim -o rig.toml` leaves beside it
    assert main(["rig", "apply-design", str(geometry), str(rig)]) == 0
    out = capsys.readouterr().out
    assert f"note: {rig} was written by 'gonio sim'" in out, out
    assert f"'gonio sim --geometry {geometry} -o {rig}'" in out, out
    # Nothing added (the same design again): nothing to say.
    assert main(["rig", "apply-design", str(geometry), str(rig)]) == 0
    assert "gonio sim" not in capsys.readouterr().out
