"""Tests of ``gonio design`` through the real CLI entry point, with a small saved basis."""

from __future__ import annotations

import tomllib
from pathlib import Path

import numpy as np
import pytest

from gonio.brdf.design.conditioning import condition_number
from gonio.brdf.design.constraints import min_pairwise_distance
from gonio.brdf.reconstruction.basis import Basis
from gonio.brdf.tables import geometry as geo
from gonio.cli import main


@pytest.fixture(scope="module")
def basis_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    # Smooth random columns over the (th, td, pd) grid stand in for a trained basis: the CLI
    # only needs rows to condition, and building the real default basis takes minutes.
    rng = np.random.default_rng(0)
    th, td, pd = (a.ravel() for a in geo.grid_angles())
    K = 8
    feats = np.stack([th, td, np.cos(2 * pd), np.sin(2 * pd)], axis=1)
    Q = np.cos(feats @ rng.normal(size=(4, K)) * 2.0 + rng.uniform(0, 6, size=K))
    basis = Basis(Q, np.linspace(2.0, 1.0, K), np.ones(geo.N_ROWS), np.zeros(geo.N_ROWS),
                  geo.valid_mask().ravel())
    return basis.save(tmp_path_factory.mktemp("basis") / "small.npz")


FAST = ["--starts", "1", "--descents", "1", "--neighbourhood", "3"]


def test_design_pairs_writes_a_rig_fragment(basis_file: Path, tmp_path: Path,
                                            capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "frag.toml"
    code = main(["design", "--pairs", "4", "--basis", str(basis_file), "--seed", "3",
                 "--min-device-distance", "12", *FAST, "-o", str(out)])
    assert code == 0
    text = capsys.readouterr().out
    assert "condition number:" in text and "roughness bound at 8 rotations" in text
    frag = tomllib.loads(out.read_text())
    assert [d["name"] for d in frag["lights"]] == ["L1", "L2", "L3", "L4"]
    assert len(frag["sensors"]) == 4 and len(frag["pairs"]) == 4
    assert frag["pairs"][2] == {"light": "L3", "sensor": "S3"}
    # The written geometry really has the printed condition number.
    basis = Basis.load(basis_file)
    li = np.deg2rad([[d["theta_deg"], d["phi_deg"]] for d in frag["lights"]])
    se = np.deg2rad([[d["theta_deg"], d["phi_deg"]] for d in frag["sensors"]])
    th, _, td, pd = geo.directions_to_half_diff(geo.spherical_to_direction(li[:, 0], li[:, 1]),
                                                geo.spherical_to_direction(se[:, 0], se[:, 1]))
    kappa = condition_number(basis.rows_at(th, td, pd))
    printed = float(text.split("condition number:")[1].split()[0].rstrip(","))
    assert kappa == pytest.approx(printed, rel=1e-3)
    assert all(d["theta_deg"] <= 80.0 + 1e-6 for d in frag["lights"] + frag["sensors"])
    # The same -o again: the fragment (the lab's mounting plan) is kept, refused before the
    # search; --overwrite replaces it.
    kept = out.read_text()
    capsys.readouterr()
    assert main(["design", "--pairs", "3", "--basis", str(basis_file), *FAST,
                 "-o", str(out)]) == 2
    assert f"{out} exists: nothing was designed" in capsys.readouterr().err
    assert out.read_text() == kept
    assert main(["design", "--pairs", "3", "--basis", str(basis_file), *FAST,
                 "-o", str(out), "--overwrite"]) == 0
    assert len(tomllib.loads(out.read_text())["pairs"]) == 3


def test_twenty_pairs_with_default_limits(basis_file: Path, tmp_path: Path,
                                          capsys: pytest.CaptureFixture[str]) -> None:
    # Default rig limits (10 deg between any two devices); a shorter search than the default.
    # The condition-number search: --starts/--descents set its length (the expected-error
    # choice ignores them and takes ~25 s for 20 pairs; it is checked under the same limits
    # in test_the_objective_is_chosen_and_reported and tests/unit/brdf/design/test_pairs.py).
    out = tmp_path / "twenty.toml"
    code = main(["design", "--pairs", "20", "--basis", str(basis_file), "--objective", "kappa",
                 "--starts", "1", "--descents", "2", "-o", str(out)])
    assert code == 0
    assert "design: optimized, 20 pairs" in capsys.readouterr().out
    frag = tomllib.loads(out.read_text())
    dev = np.deg2rad([[d["theta_deg"], d["phi_deg"]] for d in frag["lights"] + frag["sensors"]])
    dirs = geo.spherical_to_direction(dev[:, 0], dev[:, 1])
    assert len(dirs) == 40
    # From the written (rounded) angles: every two devices at least 10 deg apart.
    assert np.degrees(min_pairwise_distance(dirs)) >= 10.0 - 1e-3


def test_design_product_rig(basis_file: Path, tmp_path: Path,
                            capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "prod.toml"
    code = main(["design", "--lights", "2", "--sensors", "3", "--basis", str(basis_file),
                 "--exclude", "cone:0,0,10", *FAST, "-o", str(out)])
    assert code == 0
    assert "6 pairs" in capsys.readouterr().out
    frag = tomllib.loads(out.read_text())
    assert frag["pairs"] == "all"
    assert len(frag["lights"]) == 2 and len(frag["sensors"]) == 3
    assert all(d["theta_deg"] >= 10.0 - 1e-6 for d in frag["lights"] + frag["sensors"])


def test_design_preset(basis_file: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["design", "--preset", "ma98", "--basis", str(basis_file)]) == 0
    text = capsys.readouterr().out
    assert "design: MA98, 19 pairs" in text
    # Its nearest pair to the mirror: the 20 deg sensor under the 15 deg light, a half vector
    # tilted by (20 - 15) / 2 deg in the plane of incidence.
    assert "mirror gap: 2.5 deg" in text
    assert ("glossy specimens: no pair's half vector comes within 2.5 degrees of the specimen "
            "normal (for a pair in the plane of incidence: its sensor 5 degrees off") in text
    # A preset is compared with optimized designs by the same two numbers.
    assert "objective:" not in text and "expected log_rmse" in text
    # The scans' default arc, or a full turn when asked; any other arc is refused.
    assert "at 8 rotations over 180 deg" in text
    assert main(["design", "--preset", "ma98", "--basis", str(basis_file), "--span", "360"]) == 0
    assert "at 8 rotations over 360 deg" in capsys.readouterr().out
    with pytest.raises(SystemExit):
        main(["design", "--preset", "ma98", "--basis", str(basis_file), "--span", "90"])
    assert "invalid choice" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("argv", "match"),
    [
        (["--pairs", "0"], "--pairs must be at least 1"),
        (["--lights", "2", "--sensors", "2", "--objective", "posterior"],
         "--objective chooses --pairs designs"),
        (["--pairs", "2", "--seed", "-1"], "--seed must be at least 0"),
        (["--lights", "2"], "--lights needs --sensors"),
        (["--pairs", "2", "--sensors", "2"], "--sensors goes with --lights"),
        (["--pairs", "2", "--exclude", "ring:1"], "cone:THETA,PHI,RADIUS"),
        (["--pairs", "2", "--max-elevation", "120"], "max elevation"),
        (["--pairs", "2", "--neighbourhood", "4"], "odd number"),
        (["--preset", "XYZ"], "known presets are MA68, MA98, BYK-mac, MultiFX10"),
        (["--pairs", "2", "--basis", "/nonexistent/basis.npz"], "does not exist"),
        (["--lights", "2", "--sensors", "2", "--colour", "MA98"], "--colour designs --pairs"),
        (["--pairs", "6", "--colour", "MA98", "--objective", "kappa"],
         "without --objective kappa"),
        (["--pairs", "6", "--colour", "MA99"], "known instruments are MA68, MA98"),
        (["--pairs", "6", "--colour", "MA98", "--colour-weight", "-1"],
         "colour weight must be a number >= 0"),
        # the rig config's bound (config.py), refused before the design is computed
        (["--pairs", "6", "--colour", "MA98", "--colour-weight", "5000"],
         "--colour-weight must be between 0 and 1000"),
        (["--pairs", "3", "--colour", "MA98"], "need 5 pairs of their own"),
        (["--lights", "2", "--sensors", "2", "--render-mix", "0.5"],
         "--render-mix weighs the expected-error design of --pairs"),
        (["--pairs", "3", "--render-mix", "0.5", "--objective", "kappa"],
         "without --objective kappa"),
        (["--pairs", "3", "--render-mix", "1.5"], "--render-mix must be between 0 and 1"),
        (["--pairs", "6", "--colour", "MA98", "--render-mix", "0.5"],
         "--render-mix and --colour cannot be combined"),
        (["--pairs", "3", "--max-elevation", "5", "--min-separation", "30"],
         "no grid cell is feasible"),
        # the core names the settings to relax; the CLI words them as its flags
        (["--pairs", "3", "--max-elevation", "5", "--min-separation", "30"],
         "raise --max-elevation or lower --min-separation / --min-device-distance"),
    ],
)
def test_user_errors_are_one_clear_line(argv: list[str], match: str, basis_file: Path,
                                        capsys: pytest.CaptureFixture[str]) -> None:
    if "--basis" not in argv:
        argv = [*argv, "--basis", str(basis_file)]
    assert main(["design", *FAST, *argv]) == 2
    err = capsys.readouterr().err
    assert err.startswith("gonio design: error:") and match in err


def test_preset_with_a_repeated_cell_explains_its_infinite_condition_number(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from gonio.brdf.design.presets import get_preset

    # More components than MA98 has pairs (as the default basis, K = 64): the 19 x 19 block
    # of a repeated cell is singular.
    rng = np.random.default_rng(1)
    th_, td_, pd_ = (a.ravel() for a in geo.grid_angles())
    K = 24
    feats = np.stack([th_, td_, np.cos(2 * pd_), np.sin(2 * pd_)], axis=1)
    Q = np.cos(feats @ rng.normal(size=(4, K)) * 3.0 + rng.uniform(0, 6, size=K))
    basis_file = Basis(Q, np.linspace(2.0, 1.0, K), np.ones(geo.N_ROWS), np.zeros(geo.N_ROWS),
                       geo.valid_mask().ravel()).save(tmp_path / "k24.npz")

    # Independently of the CLI: which MA98 pairs have the same half/difference cell.
    wi, wo = get_preset("MA98").directions()
    th, _, td, pd = geo.directions_to_half_diff(wi, wo)
    cells = np.round(np.degrees(np.stack([th, td, np.mod(pd, np.pi)], axis=1)), 6)
    dup = [(i + 1, j + 1) for i in range(len(cells)) for j in range(i + 1, len(cells))
           if np.array_equal(cells[i], cells[j])]
    assert dup  # MA98 measures one cell twice
    assert main(["design", "--preset", "MA98", "--basis", str(basis_file)]) == 0
    text = capsys.readouterr().out
    assert "condition number: inf" in text
    for i, j in dup:
        assert f"pairs {i} and {j} sample the same cell" in text
    assert "the regularized solve still reconstructs" in text
    assert f"at most {19 - len(dup)} distinct cells" in text


def test_a_well_conditioned_design_gets_no_explanation(
    basis_file: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["design", "--pairs", "3", "--basis", str(basis_file), *FAST]) == 0
    text = capsys.readouterr().out
    assert "condition number: inf" not in text and "why:" not in text


@pytest.mark.parametrize("objective", ["kappa", "posterior"])
def test_the_objective_is_chosen_and_reported(objective: str, basis_file: Path, tmp_path: Path,
                                              capsys: pytest.CaptureFixture[str]) -> None:
    from gonio.brdf.design.constraints import RigConstraints
    from gonio.brdf.design.posterior import (
        design_expected_log_rmse,
        posterior_design,
        prior_model,
    )

    out = tmp_path / "frag.toml"
    assert main(["design", "--pairs", "5", "--basis", str(basis_file), "--objective",
                 objective, "--rotations", "12", *FAST, "-o", str(out)]) == 0
    text = capsys.readouterr().out
    assert "design: optimized, 5 pairs" in text
    assert f"objective: {objective} (" in text and "note:" not in text
    # Only the statistics of the search that ran.
    assert ("search:" in text) == (objective == "kappa")
    assert ("greedy choice:" in text) == (objective == "posterior")
    # The printed expected log_rmse is the joint fit's for the written geometry at 12 angles.
    basis = Basis.load(basis_file)
    frag = tomllib.loads(out.read_text())
    li = np.deg2rad([[d["theta_deg"], d["phi_deg"]] for d in frag["lights"]])
    se = np.deg2rad([[d["theta_deg"], d["phi_deg"]] for d in frag["sensors"]])
    th, _, td, pd = geo.directions_to_half_diff(geo.spherical_to_direction(li[:, 0], li[:, 1]),
                                                geo.spherical_to_direction(se[:, 0], se[:, 1]))
    rows = basis.rows_at(th, td, pd)
    # Default rig limits, from the written (rounded) angles: every two devices >= 10 deg apart.
    dirs = np.concatenate([geo.spherical_to_direction(li[:, 0], li[:, 1]),
                           geo.spherical_to_direction(se[:, 0], se[:, 1])])
    assert np.degrees(min_pairwise_distance(dirs)) >= 10.0 - 1e-3
    line = text.split("condition number:")[1].splitlines()[0]
    assert float(line.split()[0].rstrip(",")) == pytest.approx(condition_number(rows), rel=1e-3)
    printed = float(line.split("expected log_rmse")[1].split()[0])
    assert "at 12 rotations" in line
    want = design_expected_log_rmse(prior_model(basis, 12), rows)
    assert printed == pytest.approx(want, rel=1e-3, abs=1e-4)
    if objective == "posterior":
        # The cells are the expected-error design's, by default with the standard renderings'
        # pixel counts mixed in at one half (docs/science.md 7.2.2; checked against the core
        # directly, with the map counted by the renderer, not the shipped copy).
        from gonio.brdf.pictures.appearance import render_importance

        assert "weighted by the standard renderings at 0.5" in text
        assert frag["design"]["render_mix"] == 0.5
        # Retro-reflection (light and view together, td near 0) is read only when some pair's
        # difference angle, from the written lab directions, is below 15 degrees.
        assert ("broad retro-reflective lobe is read poorly" in text) == bool(
            np.degrees(td).min() >= 15.0 - 0.01), np.degrees(td)
        direct = posterior_design(basis, 5, RigConstraints(), rotations=12,
                                  cell_weight=render_importance(), cell_mix=0.5)
        written = np.stack([th, td, np.mod(pd, np.pi)], axis=1)
        for c in direct.cells:  # (the fragment holds angles rounded to 0.001 deg or so)
            gap = np.abs(written - c)
            gap[:, 2] = np.minimum(gap[:, 2], np.pi - gap[:, 2])
            assert gap.max(axis=1).min() < np.deg2rad(0.01)


def test_render_mix_designs_with_the_renderings_cell_weights(
        basis_file: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``--render-mix A``: the pairs are the core's expected-error design with the standard
    renderings' pixel counts mixed in at A (docs/science.md 7.2.2)."""
    from gonio.brdf.design.constraints import RigConstraints
    from gonio.brdf.design.posterior import posterior_design
    from gonio.brdf.pictures.appearance import render_importance

    out = tmp_path / "frag.toml"
    assert main(["design", "--pairs", "5", "--basis", str(basis_file), "--render-mix", "1",
                 "-o", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "objective: posterior (" in printed
    assert "weighted by the standard renderings at 1 (--render-mix" in printed
    basis = Basis.load(basis_file)
    frag = tomllib.loads(out.read_text())
    assert frag["design"]["render_mix"] == 1.0
    li = np.deg2rad([[d["theta_deg"], d["phi_deg"]] for d in frag["lights"]])
    se = np.deg2rad([[d["theta_deg"], d["phi_deg"]] for d in frag["sensors"]])
    th, _, td, pd = geo.directions_to_half_diff(geo.spherical_to_direction(li[:, 0], li[:, 1]),
                                                geo.spherical_to_direction(se[:, 0], se[:, 1]))
    written = np.stack([th, td, np.mod(pd, np.pi)], axis=1)
    mixed = posterior_design(basis, 5, RigConstraints(), cell_weight=render_importance(),
                             cell_mix=1.0)
    plain = posterior_design(basis, 5, RigConstraints())
    assert not np.allclose(np.sort(mixed.cells, axis=0), np.sort(plain.cells, axis=0))
    for c in mixed.cells:  # (the fragment holds rounded angles)
        gap = np.abs(written - c)
        gap[:, 2] = np.minimum(gap[:, 2], np.pi - gap[:, 2])
        assert gap.max(axis=1).min() < np.deg2rad(0.01)


def test_render_mix_zero_is_the_unweighted_design(
        basis_file: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``--render-mix 0``: the expected-error design weighing cells as log_rmse does alone
    (the design before the renderings' weighting became the default); nothing recorded."""
    from gonio.brdf.design.constraints import RigConstraints
    from gonio.brdf.design.posterior import posterior_design

    out = tmp_path / "frag.toml"
    assert main(["design", "--pairs", "5", "--basis", str(basis_file), "--render-mix", "0",
                 "--no-expected-error", "-o", str(out)]) == 0
    assert "weighted by the standard renderings" not in capsys.readouterr().out
    frag = tomllib.loads(out.read_text())
    assert "render_mix" not in frag.get("design", {})
    li = np.deg2rad([[d["theta_deg"], d["phi_deg"]] for d in frag["lights"]])
    se = np.deg2rad([[d["theta_deg"], d["phi_deg"]] for d in frag["sensors"]])
    th, _, td, pd = geo.directions_to_half_diff(geo.spherical_to_direction(li[:, 0], li[:, 1]),
                                                geo.spherical_to_direction(se[:, 0], se[:, 1]))
    written = np.stack([th, td, np.mod(pd, np.pi)], axis=1)
    plain = posterior_design(Basis.load(basis_file), 5, RigConstraints())
    for c in plain.cells:
        gap = np.abs(written - c)
        gap[:, 2] = np.minimum(gap[:, 2], np.pi - gap[:, 2])
        assert gap.max(axis=1).min() < np.deg2rad(0.01)


def test_an_unknown_objective_names_the_choices(basis_file: Path,
                                                capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        main(["design", "--pairs", "2", "--objective", "nope", "--basis", str(basis_file)])
    assert exc.value.code == 2
    assert ("argument --objective: invalid choice: 'nope' (choose from 'kappa', 'posterior')"
            in capsys.readouterr().err)


def test_a_colour_design_puts_pairs_at_the_near_specular_geometries(
        basis_file: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``--colour MA98``: MA98's in-plane geometries with aspecular angles up to 25 degrees
    (45as-15, 45as15, 45as25, 15as-15, 15as-5) are the first five pairs: light at the
    incidence, sensor at ``incidence - aspecular`` on the far side, in one plane (or light and
    sensor swapped, which reads the same by reciprocity)."""
    out = tmp_path / "colour.toml"
    assert main(["design", "--pairs", "6", "--basis", str(basis_file), "--colour", "ma98",
                 "-o", str(out)]) == 0
    assert "colour: pairs 1-5 sit at the instrument's near-specular geometries" in (
        capsys.readouterr().out)
    frag = tomllib.loads(out.read_text())
    lights = {d["name"]: (d["theta_deg"], d["phi_deg"]) for d in frag["lights"]}
    sensors = {d["name"]: (d["theta_deg"], d["phi_deg"]) for d in frag["sensors"]}
    got = []
    for pair in frag["pairs"][:5]:
        (ti, pi), (tv, pv) = lights[pair["light"]], sensors[pair["sensor"]]
        # Same plane of incidence, sensor on the far side (or on the light's side when the
        # aspecular angle passes the normal).
        turn = (pv - pi) % 360.0
        assert min(abs(turn - 180.0), abs(turn)) < 1e-6
        signed_view = tv if abs(turn - 180.0) < 1e-6 else -tv
        got.append(tuple(sorted((round(ti, 6), round(signed_view, 6)))))
    want = [tuple(sorted((float(i), float(i - a))))
            for i, a in ((45, -15), (45, 15), (45, 25), (15, -15), (15, -5))]
    assert sorted(got) == sorted(want)
    # --basis leaves out the held-out error, so [design] records only the colour design
    # (what the rig config keeps after 'gonio rig apply-design'), under its known name.
    assert frag["design"] == {"rotations": 8, "span_deg": 180.0, "pairs": 6,
                              "colour_instrument": "MA98", "colour_weight": 100.0}
    # Merged into a rig config, the record stays; the config's design is the colour design.
    rig = tmp_path / "rig.toml"
    rig.write_text((Path(__file__).resolve().parents[3] / "deploy" / "rig.example.toml")
                   .read_text())
    assert main(["rig", "apply-design", str(out), str(rig)]) == 0
    from gonio.config import load_rig_config

    design = load_rig_config(rig).design
    assert design is not None and design.expected_log_rmse is None
    assert (design.colour_instrument, design.colour_weight) == ("MA98", 100.0)


def test_render_mix_reaches_every_candidate_design(
        basis_file: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    """``--candidates K --render-mix A``: each candidate is the rendering-weighted design of its
    seed (the core's, compared by condition number), not the plain one. The small basis stands
    in for the default one and the candidates are ranked by kappa instead of the (slow) held-out
    error: what is tested is what reaches ``design_pairs``."""
    from types import SimpleNamespace
    from typing import Any

    from gonio.brdf.design import heldout
    from gonio.brdf.design.constraints import RigConstraints
    from gonio.brdf.design.pairs import design_pairs
    from gonio.brdf.pictures.appearance import render_importance
    from gonio.cli import design_command

    basis = Basis.load(basis_file)
    monkeypatch.setattr(design_command, "_load_basis", lambda _path: basis)

    def by_kappa(make: Any, seeds: Any, _rotations: int, span_deg: float) -> Any:
        designs = [(s, make(s)) for s in seeds]
        unknown = SimpleNamespace(log_rmse=np.nan, measured=np.nan, synthetic=np.nan)
        return (min(designs, key=lambda sd: sd[1].kappa)[1], unknown,
                [(s, d.kappa, np.nan) for s, d in designs])

    monkeypatch.setattr(heldout, "choose_design", by_kappa)
    assert main(["design", "--pairs", "5", "--render-mix", "1", "--candidates", "2"]) == 0
    out = capsys.readouterr().out
    mixed = design_pairs(basis, 5, RigConstraints(), seed=1, cell_weight=render_importance(),
                         cell_mix=1.0)
    plain = design_pairs(basis, 5, RigConstraints(), seed=1)
    assert f"seed 1: kappa {mixed.kappa:.4g}," in out
    assert f"seed 1: kappa {plain.kappa:.4g}," not in out


@pytest.mark.parametrize("margin_deg", [-1.0, 1.0])
def test_the_retro_line_follows_the_closest_pairs_difference_angle(
        margin_deg: float, basis_file: Path, tmp_path: Path,
        capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    """Both sides of the threshold: with it just below the written design's smallest ``td``
    (from the lab directions) the line is printed with that angle, just above it is not."""
    from gonio.cli import design_command

    out = tmp_path / "frag.toml"
    assert main(["design", "--pairs", "5", "--basis", str(basis_file), *FAST,
                 "-o", str(out)]) == 0
    capsys.readouterr()
    frag = tomllib.loads(out.read_text())
    li = np.deg2rad([[d["theta_deg"], d["phi_deg"]] for d in frag["lights"]])
    se = np.deg2rad([[d["theta_deg"], d["phi_deg"]] for d in frag["sensors"]])
    _, _, td, _ = geo.directions_to_half_diff(geo.spherical_to_direction(li[:, 0], li[:, 1]),
                                              geo.spherical_to_direction(se[:, 0], se[:, 1]))
    closest = float(np.degrees(td).min())
    monkeypatch.setattr(design_command, "RETRO_TD_DEG", closest + margin_deg)
    assert main(["design", "--pairs", "5", "--basis", str(basis_file), *FAST]) == 0
    text = capsys.readouterr().out
    if margin_deg < 0:
        assert f"difference angle td {closest:.1f} degrees" in text
        assert "try --render-mix 0" in text
    else:
        assert "retro-reflection:" not in text


def test_a_fallback_note_names_the_flags_this_command_takes(
        basis_file: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Six pairs within 50 deg of the normal, devices 25 deg apart: the expected-error choice
    cannot mount its last pair, the condition-number search makes the design, and the note
    that says so words its advice with ``gonio design``'s flags (as the command's errors do),
    not the library's setting names."""
    code = main(["design", "--pairs", "6", "--basis", str(basis_file), "--objective",
                 "posterior", "--max-elevation", "50", "--min-device-distance", "25", *FAST])
    assert code == 0
    notes = [line for line in capsys.readouterr().out.splitlines()
             if line.strip().startswith("note:")]
    assert len(notes) == 1 and "could not be mounted" in notes[0]
    assert "lower --min-device-distance" in notes[0]
    assert "min_device_distance_deg" not in notes[0]
