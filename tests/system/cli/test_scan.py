"""``gonio scan --sim`` as a user runs it: calibrated on a white reference, then measured."""

from __future__ import annotations

import json
import os
import re
from pathlib import Path

import numpy as np
import pytest

from gonio.brdf.tables import geometry as geo
from gonio.brdf.tables.geometry import lab_to_specimen
from gonio.brdf.tables.table import BRDFTable
from gonio.cli import main
from gonio.results import read_result
from gonio.sim.rig import default_material

# The first scan of a session builds the default reconstruction basis (minutes; several more
# on a machine whose cores are saturated, e.g. under `stress-ng --cpu 2`), then it is cached.
pytestmark = pytest.mark.timeout(900)


def test_sim_scan_is_calibrated_and_matches_the_material(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "scan.h5"
    argv = ["scan", "--no-export-fits",
            "--sim", "--rotations", "4", "--time-scale", "10", "--no-progress",
            "--data-dir", str(tmp_path / "data"), "-o", str(out)]
    assert main(argv) == 0
    captured = capsys.readouterr()
    assert "calibrating the simulated rig" in captured.err
    assert "in 1/sr" in captured.out
    res = read_result(out)
    assert "white reference" in res.samples.calibration["source"]
    # The headline's upper end is printed beside the estimate (docs/science.md 7.1.1): the
    # number the result file stores, to 3 decimals.
    upper = res.metrics.get("predicted_log_rmse_upper")
    assert isinstance(upper, float) and np.isfinite(upper)
    assert f"Upper end of its interval: {upper:.3f}" in captured.out
    # The summary 'gonio scan --daemon' prints too (scan_summary): the calibration the values
    # carry (a local scan on the simulated rig did not say it) and where the original is.
    assert f"  calibration: {res.samples.calibration['source']}" in captured.out
    assert str(tmp_path / "data" / "results") in captured.out.splitlines()[0]
    s = res.samples
    alpha = np.deg2rad(s.stage_angles_deg)[None, :]
    wi = lab_to_specimen(np.asarray(s.light_dirs)[:, None, :], alpha)
    wo = lab_to_specimen(np.asarray(s.sensor_dirs)[:, None, :], alpha)
    truth = default_material().eval(wi.reshape(-1, 3), wo.reshape(-1, 3)).reshape(s.values.shape)
    # Calibrated on the white reference, the measured values are the specimen's BRDF (1/sr)
    # up to the simulated sensor noise.
    rel = np.abs(s.values - truth) / np.maximum(truth, 0.05 * truth.max())
    assert float(np.median(rel)) < 0.05
    # --no-export-fits: reconstructed, without the export fits (gonio export fits them later).
    assert res.table is not None and res.factored is None and res.principled is None


def test_rig_config_calibration_is_used_until_a_calibration_job_replaces_it(
    tmp_path: Path,
) -> None:
    from gonio.calibration import CALIBRATION_FILE, Calibration, calibration_in_effect
    from gonio.config import load_rig_config

    text = Path("deploy/rig.example.toml").read_text()
    rig = tmp_path / "rig.toml"
    rig.write_text(text + '\n[[calibration.factors]]\nlight = "L1"\nsensor = "S1"\n'
                   'factor = [2.1e-5, 1.9e-5, 2.4e-5]\n')
    cfg = load_rig_config(rig)
    data = tmp_path / "data"
    assert calibration_in_effect(data, load_rig_config("deploy/rig.example.toml")).source == "none"
    from_config = calibration_in_effect(data, cfg)
    assert from_config.source == "rig config"
    assert [p.light for p in from_config.pairs] == ["L1"]
    # A calibration job's factors, once written, take over from the rig config.
    data.mkdir()
    job_cal = Calibration(source="job 7: white reference")
    (data / CALIBRATION_FILE).write_text(job_cal.model_dump_json())
    assert calibration_in_effect(data, cfg).source == "job 7: white reference"


def test_white_reference_calibration_then_a_calibrated_scan(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The lab workflow on a rig config: calibrate on the reference, then scan with it."""
    from gonio.sim.rig import SimRigOptions, start_sim_rig

    rig = tmp_path / "rig.toml"
    with start_sim_rig(SimRigOptions(time_scale=10.0, settle_s=0.0, config_path=rig)) as sim:
        sim.place_white_reference(0.99)
        cal_h5 = tmp_path / "white.h5"
        data = ["--data-dir", str(tmp_path / "data")]
        assert main(["scan", "--no-export-fits",
                     "--rig", str(rig), "--white-reference", "0.99", "--rotations", "4",
                     *data, "--no-progress", "-o", str(cal_h5)]) == 0
        cal_json = tmp_path / "white.calibration.json"
        said = capsys.readouterr().out
        assert f"--calibration {cal_json}" in said
        # It is in effect for the later scans of this data directory without --calibration
        # (it said "apply it with --calibration", as if they needed it), and it says so.
        assert f"in effect now for this rig's later scans (data directory {tmp_path / 'data'})" \
            in said, said
        assert main(["scan", "--rig", str(rig), *data, "--dry-run", "-o", os.devnull]) == 0
        assert "uncalibrated" not in capsys.readouterr().out
        sim.place_specimen(default_material())
        out = tmp_path / "scan.h5"
        assert main(["scan", "--no-export-fits",
                     "--rig", str(rig), "--calibration", str(cal_json), "--rotations",
                     "4", *data, "--no-progress", "-o", str(out)]) == 0
        assert "in 1/sr" in capsys.readouterr().out
        s = read_result(out).samples
        truth = np.stack([[sim.true_brdf(a, b, ang) for ang in s.stage_angles_deg]
                          for a, b in s.pairs])
        rel = np.abs(s.values - truth) / np.maximum(truth, 0.05 * truth.max())
        assert float(np.median(rel)) < 0.05
        # A dry run on this data directory times the finishing as that scan took it (its
        # stored seconds), beside the measuring; it counted the measuring alone before.
        from gonio.store import JobStore

        scans = [r for r in JobStore(tmp_path / "data" / "gonio.sqlite", durable=False)
                 .list_jobs(["completed"]) if r.kind != "calibration"]
        assert len(scans) == 1 and scans[0].summary is not None
        took = float(scans[0].summary["seconds"])
        assert main(["scan", "--rig", str(rig), *data, "--dry-run", "--json",
                     "-o", os.devnull]) == 0
        dr = json.loads(capsys.readouterr().out)
        assert dr["finishing_s"] == pytest.approx(took)
        assert dr["finishing_source"] == f"job {scans[0].id}'s finishing on this job store"


@pytest.mark.parametrize(
    ("extra", "words"),
    [
        (["--white-reference", "1.5"], "albedo, in (0, 1]"),
        (["--white-reference", "0.99", "--adaptive"], "takes no --adaptive"),
    ],
)
def test_bad_white_reference_requests(
    extra: list[str], words: str, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = ["scan", "--rig", "deploy/rig.example.toml", *extra, "-o", "unused.h5"]
    assert main(argv) == 2
    assert words in capsys.readouterr().err


def test_scan_leaves_only_its_output_and_the_store_keeps_a_real_result_path(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """-o OUT.h5 writes OUT.h5 (and nothing else there); the job store lives in the data
    directory, named on stderr, and its result_path exists after the scan."""
    import json

    from gonio.paths import scan_data_dir
    from gonio.sim.rig import SimRigOptions, start_sim_rig

    rig = tmp_path / "rig" / "rig.toml"
    rig.parent.mkdir()
    outdir = tmp_path / "out"
    outdir.mkdir()
    with start_sim_rig(SimRigOptions(time_scale=10.0, settle_s=0.0, config_path=rig)) as sim:
        sim.place_white_reference(0.99)
        assert main(["scan", "--no-export-fits",
                     "--rig", str(rig), "--white-reference", "0.99", "--rotations", "4",
                     "--no-progress", "-o", str(outdir / "white.h5")]) == 0
        sim.load("specimen")
        assert main(["scan", "--no-export-fits",
                     "--rig", str(rig), "--rotations", "3", "--no-progress",
                     "-o", str(outdir / "felt.h5")]) == 0
        captured = capsys.readouterr()
        # The default data directory: one per rig geometry in the (test) user data folder.
        data = scan_data_dir(sim.config)
        assert data.parent.parent == Path(os.environ["GONIO_DATA_DIR"])
        assert f"data directory {data}" in captured.err
        # The calibration job's factors are in effect for the next scan on this rig.
        assert "in 1/sr" in captured.out
    assert sorted(p.name for p in outdir.iterdir()) == [
        "felt.h5", "white.calibration.json", "white.h5"]
    assert sorted(p.name for p in rig.parent.iterdir()) == ["rig.toml"]
    assert main(["jobs", "--db", str(data / "gonio.sqlite"), "show", "2", "--json"]) == 0
    row = json.loads(capsys.readouterr().out)
    assert row["state"] == "completed"
    # Stored relative to the data directory; `jobs show` says where that is.
    assert row["result_path"] == "results/job-2.h5"
    assert Path(row["result_file"]) == data / "results" / "job-2.h5"
    assert read_result(row["result_file"]).samples.values.shape == (12, 3, 3)
    # Without --json the lines say what the scan measured (only --json had it): the rig's 12
    # pairs x 3 angles, in 1/sr (calibrated above), and the headline error as stored.
    assert main(["jobs", "--db", str(data / "gonio.sqlite"), "show", "2"]) == 0
    text = capsys.readouterr().out
    assert (f"  measured: 36 samples in 1/sr, predicted_log_rmse "
            f"{row['result']['predicted_log_rmse']:.3f}") in text, text
    assert "  calibration: job 1" in text, text
    # A calibration job shows none of it (it has no reconstruction).
    assert main(["jobs", "--db", str(data / "gonio.sqlite"), "show", "1"]) == 0
    assert "measured:" not in capsys.readouterr().out
    # The result reconstructed again from the command line, by V&F's path (it was refused
    # as "not a gonio samples file"): the rig's 12 pairs at the scan's 3 angles.
    again = tmp_path / "felt-vf.npz"
    assert main(["reconstruct", str(outdir / "felt.h5"), "--method", "vf", "-o",
                 str(again)]) == 0
    said = capsys.readouterr()
    assert "n=12 r=3 method=vf" in said.out, said.out
    assert "sensor units" not in said.err  # calibrated above
    assert BRDFTable.load(again).values.shape[1:] == geo.TABLE_SHAPE
    # A dark pair's dark-subtracted reading just below 0 (noise): taken as 0, as the job's own
    # finishing does; reconstruct refused the whole file ("samples contain negative BRDF
    # values") with nothing the user could clamp.
    import shutil

    import h5py

    noisy = Path(shutil.copyfile(outdir / "felt.h5", tmp_path / "noisy.h5"))
    with h5py.File(noisy, "a") as f:
        values = f["samples"]["values"][...]
        values[0, 0, 0] = -1e-4
        f["samples"]["values"][...] = values
    assert main(["reconstruct", str(noisy), "--method", "vf", "-o",
                 str(tmp_path / "noisy.npz")]) == 0
    assert f"note: 1 of {values.size} readings below 0" in capsys.readouterr().err
    # The calibration job's result holds the white reference's readings: refused, saying so.
    assert main(["reconstruct", str(outdir / "white.h5"), "-o", str(tmp_path / "w.npz")]) == 2
    assert "is a calibration job's result" in capsys.readouterr().err


def test_dry_run_prints_a_short_summary_and_json_on_request(
    capsys: pytest.CaptureFixture[str]
) -> None:
    import json

    argv = ["scan", "--rig", "deploy/rig.example.toml", "--dry-run", "--rotations", "6",
            "-o", "/dev/null"]
    assert main(argv) == 0
    text = capsys.readouterr().out
    lines = text.strip().splitlines()
    assert len(lines) <= 9
    # The example rig: 2 lights x 2 sensors, all pairs; 6 angles over the default half turn,
    # 180 / 6 = 30 deg apart.
    assert "stage angles: 6 (0, 30, 60, 90, 120, 150 deg)" in text
    assert "readings: 24 (4 pairs x 6 angles), exposure 0.01 s x 1" in text
    assert "duration: about" in text
    # Then the finishing, which the measuring's estimate does not hold.
    assert "then finishing (reconstruction and export fits): about" in text
    assert main([*argv, "--json"]) == 0
    full = json.loads(capsys.readouterr().out)
    assert full["readings"] == 24 and len(full["positions_deg"]) == 6
    # --json alone is a mistake worth a clear line.
    assert main(["scan", "--rig", "deploy/rig.example.toml", "--json", "-o", "x.h5"]) == 2
    assert "--json goes with --dry-run" in capsys.readouterr().err


def test_a_dry_run_of_one_angle_says_one_angle(capsys: pytest.CaptureFixture[str]) -> None:
    """A count of one reads "1 angle", not "1 angles" (and a dry run needs no -o)."""
    assert main(["scan", "--rig", "deploy/rig.example.toml", "--dry-run", "--rotations", "1"]) == 0
    text = capsys.readouterr().out
    assert "readings: 4 (4 pairs x 1 angle), exposure" in text, text


def test_a_sim_dry_run_states_the_calibration_the_scan_runs_first(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``gonio scan --sim --dry-run`` said nothing of the white-reference calibration the scan
    runs first on a data directory with none, and a one-angle plan read "about 0 s"."""
    import json
    import re

    data = tmp_path / "data"
    dry = ["scan", "--sim", "--dry-run", "--data-dir", str(data), "-o", "/dev/null"]
    assert main([*dry, "--rotations", "1"]) == 0
    text = capsys.readouterr().out
    assert "before it, about" in text and "calibrated on a white reference" in text, text
    assert main([*dry, "--rotations", "1", "--json"]) == 0
    seconds = json.loads(capsys.readouterr().out)["estimated_s"]
    shown = re.search(r"duration: about ([0-9.]+) s", text)
    assert shown is not None and 0 < seconds < 1, text
    assert abs(float(shown.group(1)) - seconds) <= 0.05, (text, seconds)
    # The scan calibrates the rig; a dry run of the next one has nothing to run first, unless
    # it reads at another exposure (the calibration serves its own exposure only).
    assert main(["scan", "--sim", "--rotations", "2", "--no-export-fits", "--no-progress",
                 "--data-dir", str(data), "-o", str(tmp_path / "felt.h5")]) == 0
    assert "calibrating the simulated rig" in capsys.readouterr().err
    assert main([*dry, "--rotations", "2"]) == 0
    assert "before it" not in capsys.readouterr().out
    assert main([*dry, "--rotations", "2", "--exposure", "0.02"]) == 0
    assert "calibrated on a white reference" in capsys.readouterr().out


def test_a_dry_run_on_a_spectral_rig_times_its_longer_first_finishing(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Before any scan, the dry run timed a 31-band rig's finishing as the RGB rig's 7.5 s
    (it took 9.5-9.9 s); it now adds 0.1 s a channel beyond three: 7.5 + 28 x 0.1 s."""
    import json

    assert main(["scan", "--sim", "--material", "metallic-blue-paint", "--dry-run", "--json",
                 "--data-dir", str(tmp_path / "data"), "-o", os.devnull]) == 0
    dr = json.loads(capsys.readouterr().out)
    assert dr["finishing_s"] == pytest.approx(10.3), dr
    assert "28 channels beyond three" in dr["finishing_source"], dr


def test_a_store_holding_rgb_and_spectral_scans_times_each_rig_by_its_own(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The RGB simulated rig and the 31-band one can share a data directory (one named with
    --data-dir; by default each has its own since 2026-11-29); each dry run's finishing rests
    on the scans read with its own channels (the stored rigs'), not on the median of both
    kinds."""
    import json

    from gonio.store import JobStore

    data = ["--data-dir", str(tmp_path / "data")]
    spectral = ["--material", "metallic-blue-paint"]
    for extra, out in (([], "rgb.h5"), (spectral, "spectral.h5")):
        assert main(["scan", "--sim", *extra, "--rotations", "2", "--no-export-fits",
                     "--no-progress", *data, "-o", str(tmp_path / out)]) == 0
    capsys.readouterr()
    scans = [r for r in JobStore(tmp_path / "data" / "gonio.sqlite", durable=False)
             .list_jobs(["completed"]) if r.kind != "calibration"]
    assert len(scans) == 2 and all(r.summary is not None for r in scans)
    rgb, band = sorted(scans, key=lambda r: r.id)  # scanned in that order
    for extra, job, channels in (([], rgb, 3), (spectral, band, 31)):
        assert main(["scan", "--sim", *extra, "--dry-run", "--json", *data,
                     "-o", os.devnull]) == 0
        dr = json.loads(capsys.readouterr().out)
        assert job.summary is not None
        assert dr["finishing_s"] == pytest.approx(float(job.summary["seconds"])), dr
        assert dr["finishing_source"] == (
            f"job {job.id}'s finishing on this job store; scans read with other than "
            f"{channels} channels are not counted"), dr


def test_switching_between_rgb_and_spectral_sensors_keeps_each_calibration(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """Without --data-dir, the RGB and the 31-band simulated rig shared one data directory (the
    geometry's), so every switch found the other's calibration and measured its own again;
    each sensor set now has its own directory, and coming back finds the calibration."""
    from gonio.paths import DATA_ENV

    monkeypatch.setenv(DATA_ENV, str(tmp_path / "gonio-data"))
    spectral = ["--material", "metallic-blue-paint"]
    folders = []
    for extra, out, calibrates in (([], "rgb1.h5", True), (spectral, "band.h5", True),
                                   ([], "rgb2.h5", False)):
        assert main(["scan", "--sim", *extra, "--rotations", "2", "--no-export-fits",
                     "--no-progress", "-o", str(tmp_path / out)]) == 0
        err = capsys.readouterr().err
        assert ("calibrating the simulated rig" in err) is calibrates, (out, err)
        folder = re.search(r"data directory (\S+) ", err)
        assert folder is not None, err
        folders.append(folder.group(1))
    assert folders[0] == folders[2] != folders[1], folders


def test_an_adaptive_dry_run_states_its_cap_and_refuses_a_cap_below_the_start(
    capsys: pytest.CaptureFixture[str]
) -> None:
    """The posterior rule stops at --max-rotations (default 16): the summary's bound says so;
    a cap below the first round is a clear error, not a plan that cannot run."""
    argv = ["scan", "--rig", "deploy/rig.example.toml", "--dry-run", "--adaptive",
            "-o", "/dev/null"]
    assert main(argv) == 0
    text = capsys.readouterr().out
    assert "stage angles: 4 in the first round" in text
    assert "at most 16 angles and" in text
    assert main([*argv, "--max-rotations", "10"]) == 0
    assert "at most 10 angles and" in capsys.readouterr().out
    assert main([*argv, "--max-rotations", "3"]) == 2
    err = capsys.readouterr().err
    assert "max_rotations 3 is fewer than the first round's 4 angles" in err
    with pytest.raises(SystemExit):  # argparse: a count > 0
        main([*argv, "--max-rotations", "0"])
    assert "--max-rotations" in capsys.readouterr().err


@pytest.mark.parametrize("extra", [["--rule", "vf"], ["--min-gain", "0.001"],
                                   ["--max-rotations", "10"], ["--threshold", "0.05"],
                                   ["--max-samples", "200"]])
def test_adaptive_options_without_adaptive_are_refused_not_dropped(
    extra: list[str], capsys: pytest.CaptureFixture[str]
) -> None:
    """'gonio scan --rule vf' (no --adaptive) ran the default uniform scan, the option
    silently dropped; so did the other adaptive-only options."""
    argv = ["scan", "--rig", "deploy/rig.example.toml", "--dry-run", "-o", "/dev/null"]
    assert main([*argv, *extra]) == 2
    err = capsys.readouterr().err
    assert f"{extra[0]} only apply to an adaptive scan: add --adaptive" in err, err
    assert main([*argv, "--adaptive", *extra]) == 0
    assert "dry run of the adaptive plan" in capsys.readouterr().out


def test_scan_sim_keeps_its_own_data_directory_apart_from_a_sim_rigs(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """`gonio sim` (the README's simulated rig) and `gonio scan --sim` simulate the same
    geometry, and both used `scans/sim-<hash>`: a `gonio scan --sim --exposure 0.02`
    calibrated there and replaced the rig's morning calibration at 0.01 s, after which the
    rig's scans at 0.01 s were refused. `gonio scan --sim` now keeps its own data directory
    (`scan-sim/` in the user data folder); the rig's calibration stays as it was."""
    from gonio.calibration import calibration_in_effect
    from gonio.paths import scan_data_dir
    from gonio.sim.rig import SimRigOptions, start_sim_rig

    rig = tmp_path / "rig.toml"
    with start_sim_rig(SimRigOptions(time_scale=10.0, settle_s=0.0, config_path=rig)) as sim:
        sim.place_white_reference(0.99)
        assert main(["scan", "--no-export-fits", "--rig", str(rig), "--white-reference",
                     "0.99", "--rotations", "2", "--no-progress",
                     "-o", str(tmp_path / "white.h5")]) == 0
        own = scan_data_dir(sim.config)
    before = calibration_in_effect(own, sim.config)
    assert before.exposure_s == pytest.approx(0.01)
    capsys.readouterr()
    assert main(["scan", "--sim", "--exposure", "0.02", "--rotations", "2", "--time-scale",
                 "10", "--no-export-fits", "--no-progress", "-o", str(tmp_path / "s.h5")]) == 0
    err = capsys.readouterr().err
    root = Path(os.environ["GONIO_DATA_DIR"])
    said = re.search(r"data directory (\S+) ", err)
    assert said is not None, err
    assert Path(said.group(1)).parent == root / "scan-sim", err
    # The rig's calibration is the one it had: at 0.01 s, from its own job.
    after = calibration_in_effect(own, sim.config)
    assert after.exposure_s == pytest.approx(0.01) and after.source == before.source
