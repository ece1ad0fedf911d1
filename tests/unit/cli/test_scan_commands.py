"""'gonio scan' and 'gonio jobs' (gonio.cli.scan_commands, gonio.cli.jobs_command): the
plan built from the options, user errors, the job list (no rig needed)."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import pytest

from gonio.cli import UsageError, build_parser, jobs_command, scan_commands, scan_report
from gonio.cli.scan_commands import _plan
from gonio.plans.models import AdaptivePlan, CalibrationPlan, UniformPlan
from gonio.store import JobStore


def _parse(*argv: str) -> object:
    return _plan(build_parser().parse_args(["scan", "--rig", "rig.toml", "-o", "x.h5", *argv]))


def test_white_reference_job_is_named_after_the_reference_not_the_specimen() -> None:
    # The calibration's source line ("calibration: job 1: ...") and 'gonio jobs list' show
    # this name; before, an unnamed reference was called "specimen".
    plan = _parse("--white-reference", "0.99")
    assert isinstance(plan, CalibrationPlan) and plan.reference_name == "white reference"
    named = _parse("--white-reference", "0.99", "--specimen", "spectralon-99")
    assert isinstance(named, CalibrationPlan) and named.reference_name == "spectralon-99"
    # The job's own name (the job list, the page, the result's specimen) is the reference's
    # too: it was the plans' default "specimen".
    assert plan.specimen == "white reference" and named.specimen == "spectralon-99"


def test_scan_keeps_its_specimen_names() -> None:
    # Unnamed: after the result file (-o x.h5), not "specimen" for every scan.
    plan = _parse()
    assert isinstance(plan, UniformPlan) and plan.specimen == "x"
    felt = _parse("--specimen", "felt")
    assert isinstance(felt, UniformPlan) and felt.specimen == "felt"
    # A generic output name says nothing of the specimen: "unnamed", which exports state.
    generic = _plan(build_parser().parse_args(["scan", "--sim", "-o", "out/result.h5"]))
    assert isinstance(generic, UniformPlan) and generic.specimen == "unnamed"


def test_adaptive_scans_take_the_rule_and_its_defaults() -> None:
    plan = _parse("--adaptive")
    assert isinstance(plan, AdaptivePlan)
    assert (plan.rule, plan.initial_rotations, plan.min_gain) == ("posterior", 4, 2e-5)
    vf = _parse("--adaptive", "--rule", "vf", "--threshold", "0.05")
    assert isinstance(vf, AdaptivePlan)
    assert (vf.rule, vf.initial_rotations, vf.threshold) == ("vf", 8, 0.05)
    mine = _parse("--adaptive", "--rotations", "6", "--min-gain", "0.002")
    assert isinstance(mine, AdaptivePlan)
    assert (mine.initial_rotations, mine.min_gain) == (6, 0.002)
    assert (plan.max_rotations, vf.max_rotations) == (16, None)
    capped = _parse("--adaptive", "--max-rotations", "10")
    assert isinstance(capped, AdaptivePlan) and capped.max_rotations == 10
    # Without --adaptive, --rotations keeps its default of 8.
    uniform = _parse()
    assert isinstance(uniform, UniformPlan) and uniform.rotations == 8


def test_scans_cover_half_a_turn_unless_told() -> None:
    uniform, full = _parse(), _parse("--span", "360")
    assert isinstance(uniform, UniformPlan) and uniform.span_deg == 180.0
    assert isinstance(full, UniformPlan) and full.span_deg == 360.0
    adaptive, vf = _parse("--adaptive"), _parse("--adaptive", "--rule", "vf")
    assert isinstance(adaptive, AdaptivePlan) and adaptive.span_deg == 180.0
    assert isinstance(vf, AdaptivePlan) and vf.span_deg == 360.0  # V&F's full turn
    vf_half = _parse("--adaptive", "--rule", "vf", "--span", "180")
    assert isinstance(vf_half, AdaptivePlan) and vf_half.span_deg == 180.0


def test_other_arcs_are_refused(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        _parse("--span", "90")
    assert "invalid choice" in capsys.readouterr().err


def _args(argv: list[str]) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="gonio")
    sub = parser.add_subparsers(dest="command")
    scan_commands.register(sub)
    jobs_command.register(sub)
    return parser.parse_args(argv)


def test_cli_user_errors(tmp_path: Path) -> None:
    args = _args(["scan", "--rig", str(tmp_path / "missing.toml"), "-o", str(tmp_path / "o.h5")])
    with pytest.raises(UsageError, match="does not exist"):
        args.func(args)
    with pytest.raises(SystemExit):  # argparse: "--exposure: expected a finite number > 0"
        _args(["scan", "--sim", "--exposure", "0", "-o", str(tmp_path / "o.h5")])
    args = _args(["jobs", "--db", str(tmp_path / "none.sqlite")])
    with pytest.raises(UsageError, match=r"job store .* does not exist"):
        args.func(args)
    JobStore(tmp_path / "j.sqlite").create_job(kind="uniform", specimen="x", plan={}, rig={})
    args = _args(["jobs", "show", "--db", str(tmp_path / "j.sqlite")])
    with pytest.raises(UsageError, match="needs a job id"):
        args.func(args)
    args = _args(["jobs", "show", "9", "--db", str(tmp_path / "j.sqlite")])
    with pytest.raises(UsageError, match="no job with id 9"):
        args.func(args)


def test_jobs_show_reads_each_job_once_and_probes_the_store_lock_once(
        tmp_path: Path, capsys: pytest.CaptureFixture[str],
        monkeypatch: pytest.MonkeyPatch) -> None:
    """``gonio jobs show`` of a queued job read its row, then the whole job list (every job's
    plan and rig decoded, its own again) to say why it waits; of a running job no process
    runs, it took the store's lock twice (once to find a daemon, once for the note). Each is
    read once now; what it prints is the same."""
    import gonio.locks

    db = tmp_path / "gonio.sqlite"
    store = JobStore(db)
    ids = [store.create_job(kind="uniform", specimen=name, plan={}, rig={}).id
           for name in ("done", "measuring", "held", "waiting")]
    for state in ("running", "reconstructing", "completed"):
        store.set_state(ids[0], state)
    store.set_state(ids[1], "running")
    store.set_state(ids[2], "running")
    store.set_state(ids[2], "paused")  # the queue waits for it
    read: list[int] = []
    for name in ("get_job", "list_jobs", "queue"):
        def spy(self: JobStore, *a: object, _orig: object = getattr(JobStore, name),
                **k: object) -> object:
            got = _orig(self, *a, **k)  # type: ignore[operator]
            read.extend(r.id for r in (got if isinstance(got, list) else [got]))
            return got
        monkeypatch.setattr(JobStore, name, spy)
    probes: list[object] = []
    claim = gonio.locks.claim_store
    monkeypatch.setattr(gonio.locks, "claim_store",
                        lambda *a, **k: probes.append(a) or claim(*a, **k))

    args = _args(["jobs", "show", str(ids[3]), "--db", str(db)])
    assert args.func(args) == 0
    out = capsys.readouterr().out
    assert sorted(read) == sorted(set(read)), read  # no job read twice
    assert ids[0] not in read  # a completed job says nothing of why a queued one waits
    assert f"job {ids[3]}: uniform 'waiting', queued" in out
    assert f"waiting: waits for job {ids[2]} (paused): resume or abort it" in out, out
    assert "queue position: 0 (0 = next)" in out

    read.clear()
    args = _args(["jobs", "show", str(ids[1]), "--db", str(db)])
    assert args.func(args) == 0
    out = capsys.readouterr().out
    assert len(probes) == 2, probes  # one probe per show
    assert f"job {ids[1]}: uniform 'measuring', running" in out
    assert out.count("note: no daemon or gonio scan runs jobs from this store now") == 1, out
    assert f"with job(s) {ids[1]} above: they were interrupted" in out


def test_cli_jobs_list(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    JobStore(tmp_path / "j.sqlite").create_job(kind="uniform", specimen="felt", plan={}, rig={})
    args = _args(["jobs", "list", "--db", str(tmp_path / "j.sqlite")])
    assert args.func(args) == 0
    out = capsys.readouterr().out
    assert "queued" in out and "felt" in out
    # Nothing runs the store (its daemon stopped or killed): the queued job says it waits
    # for one; it showed no reason, as if about to start (a newcomer's review, after kill -9).
    assert "(no daemon runs this store now: queued jobs start when a daemon ('gonio serve') " \
        "runs it again" in out, out
    # With another process holding the store's lock (as a daemon does), that is not said.
    import subprocess
    import sys

    holder = subprocess.Popen(
        [sys.executable, "-c", "import sys, time; from gonio.locks import claim_store; "
         "lock = claim_store(sys.argv[1]); print('held', flush=True); time.sleep(30)",
         str(tmp_path / "j.sqlite")], stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout is not None and holder.stdout.readline().strip() == "held"
        assert args.func(args) == 0
        assert "no daemon runs this store" not in capsys.readouterr().out
    finally:
        holder.kill()
        holder.wait(timeout=30)


@pytest.mark.parametrize("action", [[], ["list"], ["show", "3"], ["abort", "3"],
                                    ["rebuild", "3"]])
def test_jobs_without_a_store_says_where_it_looked_and_what_to_pass(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch,
    action: list[str],
) -> None:
    # It was argparse's "the following arguments are required: --db" alone.
    from gonio.cli import main

    monkeypatch.setenv("GONIO_DATA_DIR", str(tmp_path / "data"))
    monkeypatch.chdir(tmp_path)
    assert main(["jobs", *action]) == 2
    err = capsys.readouterr().err
    assert "--db DATA_DIR/gonio.sqlite" in err
    assert str(tmp_path / "data" / "scans" / "*" / "gonio.sqlite") in err
    assert str(tmp_path / "data" / "serve-sim" / "gonio.sqlite") in err
    # The stores that are there are named, each as the --db to pass.
    store = tmp_path / "data" / "scans" / "sim-201fe981" / "gonio.sqlite"
    store.parent.mkdir(parents=True)
    JobStore(store).create_job(kind="uniform", specimen="felt", plan={}, rig={})
    assert main(["jobs", *action]) == 2
    assert f"--db {store}" in capsys.readouterr().err


def test_the_arc_options_build_an_auto_arc_plan_or_say_what_is_wrong() -> None:
    auto = _parse("--arc", "auto")
    assert isinstance(auto, UniformPlan) and (auto.arc, auto.span_deg) == ("auto", 180.0)
    vf = _parse("--arc", "auto", "--adaptive", "--rule", "vf", "--arc-noise", "0.02")
    assert isinstance(vf, AdaptivePlan) and (vf.arc, vf.span_deg, vf.arc_noise) == (
        "auto", 180.0, 0.02)
    assert _parse().arc == "fixed"  # type: ignore[attr-defined]
    with pytest.raises(UsageError, match="--span 360 forces a full turn"):
        _parse("--arc", "auto", "--span", "360")
    with pytest.raises(UsageError, match="add --arc auto or drop --arc-noise"):
        _parse("--arc-noise", "0.02")


def test_the_dry_run_summary_states_both_branches_of_an_auto_arc_plan() -> None:
    from gonio.plans.dryrun import dry_run
    from gonio.rigdescription import RigDescription
    from gonio.sim.memrig import MemRig

    plan = _parse("--arc", "auto")
    text = scan_report.dry_run_summary(
        dry_run(plan, RigDescription.from_rig(MemRig())), plan, "mem")  # type: ignore[arg-type]
    # MemRig: 3 pairs in planes within 12 deg of each other (two opposites,
    # gonio.plans.arc.opposites_needed); 8 over half a turn plus 2 opposites, or 16 over the
    # full turn.
    assert "twofold symmetric: it goes on over half a turn, at most 10 angles (30 readings)" in text
    assert ("not twofold symmetric: it goes on over a full turn, at most 16 angles "
            "(48 readings)") in text
    # The full turn is reconstructed with the basis for specimens without twofold symmetry,
    # and its build (not done yet on this install) is stated with its time.
    assert "16 angles (48 readings) and" in text
    assert "reconstructed with the basis for specimens without twofold symmetry" in text
    assert "more: that basis" not in text  # built (None): nothing to wait for
    built_later = scan_report.dry_run_summary(
        dry_run(plan, RigDescription.from_rig(MemRig()), asymmetric_build_s=240.0),  # type: ignore[arg-type]
        plan, "mem")  # type: ignore[arg-type]
    assert "then about 4.0 min more: that basis is not built on this install yet" in built_later


def test_the_dry_run_summary_states_each_part_of_the_duration_to_a_few_per_cent() -> None:
    import re

    from gonio.plans.dryrun import dry_run
    from gonio.rigdescription import RigDescription
    from gonio.sim.memrig import MemRig

    desc = RigDescription.from_rig(MemRig())
    for argv in (("--rotations", "1", "--exposure", "0.05"),
                 ("--rotations", "6", "--exposure", "0.01"), ("--rotations", "24",)):
        plan = _parse(*argv)
        dr = dry_run(plan, desc)  # type: ignore[arg-type]
        text = scan_report.dry_run_summary(dr, plan, "mem")
        m = re.search(r"moves ([\d.]+) s, settling ([\d.]+) s, exposures ([\d.]+) s", text)
        assert m is not None, text
        # Each part as printed is within 5 % of the dry run's own (0.25 s printed as "0.2 s"
        # was 20 % off); exposures: every light at every angle plus one dark, each exposure
        # times its averages (docs/api.md), not the dry run's own sum.
        exposures = (len(dr.lights) * len(dr.angles_deg) + 1) * plan.exposure.exposure_s \
            * plan.exposure.averages  # type: ignore[attr-defined]
        for shown, true in zip(map(float, m.groups()), (dr.motion_s, dr.settle_s, exposures),
                               strict=True):
            assert shown == pytest.approx(true, rel=0.05, abs=1e-9), (argv, text)


def test_a_time_scaled_dry_run_says_its_durations_are_a_real_rigs_and_the_wall_time(
) -> None:
    """At ``--time-scale 10`` the dry run stated the rig's seconds as if they were the wall
    clock's. The simulated rig scales moves and exposures; the lamps' settling is the engine's
    own wait."""
    import re

    from gonio.plans.dryrun import dry_run
    from gonio.rigdescription import RigDescription
    from gonio.sim.memrig import MemRig

    plan = _parse("--rotations", "24", "--exposure", "0.05")
    dr = dry_run(plan, RigDescription.from_rig(MemRig()))  # type: ignore[arg-type]
    assert "a real rig's time" not in scan_report.dry_run_summary(dr, plan, "mem")
    text = scan_report.dry_run_summary(dr, plan, "mem", time_scale=10.0)
    m = re.search(r"at --time-scale 10 moves and exposes that much faster: about ([\d.]+) s "
                  r"of wall time", text)
    assert m is not None, text
    wall = (dr.motion_s + dr.exposure_s) / 10.0 + dr.settle_s
    assert abs(float(m.group(1)) - wall) <= 0.5, (text, wall)  # shown in whole seconds


def test_a_rebuild_says_why_its_design_comparison_is_missing_or_off() -> None:
    lost = "not available: job 3 was finished by a gonio whose job store did not keep ..."
    assert (jobs_command.design_comparison_line({"design_comparison": lost})
            == f"design comparison: {lost}")
    gap = "predicted_log_rmse 0.0997 is 2.7 times the design's expected 0.0370 ..."
    assert (jobs_command.design_comparison_line({"design_expected_log_rmse": 0.037,
                                                  "design_gap": gap})
            == f"design comparison: {gap}")
    # Within x2 of the design, or a rig without a [design]: nothing to say.
    assert jobs_command.design_comparison_line({"design_expected_log_rmse": 0.037}) is None
    assert jobs_command.design_comparison_line({"predicted_log_rmse": 0.05}) is None


def test_a_rebuild_says_when_an_import_since_changed_the_result() -> None:
    # A table imported after the scan became the rebuilt fit's local prior and moved its
    # numbers (job 2 of a lab day: 0.0511 -> 0.0512, the factored fit's error x6), while the
    # rebuild said only that it wrote the file.
    line = jobs_command.rebuild_change_line(
        {"local_prior": None, "predicted_log_rmse": 0.051054},
        {"local_prior": "felt", "predicted_log_rmse": 0.051166})
    assert line is not None and "it now leans on 'felt' where no pair looks" in line, line
    assert "0.0511 -> 0.0512" in line and "today's library" in line, line
    gone = jobs_command.rebuild_change_line({"local_prior": "felt"}, {"local_prior": None})
    assert gone is not None and "no longer leans on a local prior (it leaned on 'felt')" in gone
    assert jobs_command.rebuild_change_line({"local_prior": "felt"},
                                             {"local_prior": "felt"}) is None
    assert jobs_command.rebuild_change_line({}, {"local_prior": "felt"}) is None


def test_the_daemon_job_list_states_a_queued_jobs_estimated_start() -> None:
    """``gonio jobs --daemon URL list`` said why a queued job waits but not when it starts,
    which the API's rows carry (starts_in_s, starts_in_bound)."""
    row = {"state": "queued", "starts_in_s": 270.0, "starts_in_bound": False}
    assert scan_report.start_text(row) == "starts in about 4.5 min"
    assert scan_report.start_text({**row, "starts_in_bound": True}) == "starts within 4.5 min"
    assert scan_report.start_text({**row, "starts_in_s": 42.0}) == "starts in about 42 s"
    assert scan_report.start_text({**row, "starts_in_s": 0.0}) == "starts next"
    # Not known (the row's waiting says why), or not queued: nothing.
    assert scan_report.start_text({**row, "starts_in_s": None}) is None
    assert scan_report.start_text({**row, "state": "running"}) is None


def test_a_queued_job_followed_says_what_it_waits_for() -> None:
    """``gonio jobs --daemon URL wait`` on a queued job: the holder, the jobs ahead and the
    start, from the API's rows; said again only when what it waits for changes (the
    estimate counts down at every poll). The real daemon's lines:
    tests/system/api/test_cli_daemon_wait.py."""
    row = {"state": "queued", "waiting": None, "queue_position": 2, "starts_in_s": 42.0,
           "starts_in_bound": False,
           "starts_in_estimate": "job 5's time left plus the estimated durations of jobs 6 "
                                 "and 8 ahead"}
    jobs = [{"id": 4, "state": "completed"}, {"id": 5, "state": "running"},
            {"id": 6, "state": "queued"}, {"id": 7, "state": "queued"}]
    key, text = scan_report.queued_line(7, row, jobs)
    assert text == ("job 7 queued: waits for job 5 (running) to end; 2 queued jobs ahead of "
                    "it; starts in about 42 s (job 5's time left plus the estimated durations "
                    "of jobs 6 and 8 ahead)")
    # Ten seconds later: the same wait, not said again.
    assert scan_report.queued_line(7, {**row, "starts_in_s": 32.0}, jobs)[0] == key
    # The job ahead paused: the API's waiting says so, and the start is not known.
    paused = {**row, "waiting": "waits for job 5 (paused): resume or abort it",
              "queue_position": 0, "starts_in_s": None,
              "starts_in_estimate": "not known: waits for job 5 (paused): resume or abort it"}
    jobs[1] = {"id": 5, "state": "paused"}
    key2, text = scan_report.queued_line(7, paused, jobs)
    assert key2 != key
    assert text == ("job 7 queued: waits for job 5 (paused): resume or abort it; its start is "
                    "not known until then")
    # Nothing holds the rig and nothing is ahead, but no start estimate (a full disk).
    free = {**row, "queue_position": 0, "starts_in_s": None,
            "starts_in_estimate": "not known: no job starts while disk full: ..."}
    assert scan_report.queued_line(7, free, jobs[:1])[1] == (
        "job 7 queued: next in the queue, the rig is free; start not known: no job starts "
        "while disk full: ...")


def test_the_printed_wait_command_says_overwrite_when_its_file_exists(tmp_path: Path) -> None:
    """``gonio scan --daemon ... --overwrite -o felt.h5`` stopped while following printed
    ``... wait ID -o felt.h5``, which the existing file then refused."""
    from gonio.cli.daemon_jobs import wait_command

    out = tmp_path / "felt.h5"
    assert wait_command("http://h:1", 3, out) == f"gonio jobs --daemon http://h:1 wait 3 -o {out}"
    out.write_bytes(b"yesterday's")
    assert wait_command("http://h:1", 3, out).endswith(f"-o {out} --overwrite")
    assert scan_report._duration_text(0.0) == "0 s"
    assert scan_report._duration_text(0.19) == "0.2 s"


def test_the_queued_line_neither_repeats_under_a_hold_nor_guesses_its_place() -> None:
    """Under a held queue a reconstructing job that ends changed the line's key, so the same
    line was printed again; an answer without queue_position read "next in the queue"."""
    row = {"state": "queued", "waiting": "the queue is held (emergency halt)",
           "queue_position": 1, "starts_in_s": None, "starts_in_estimate": "not known: held"}
    busy = [{"id": 6, "state": "reconstructing"}]
    k1, t1 = scan_report.queued_line(7, row, busy)
    k2, t2 = scan_report.queued_line(7, row, [{"id": 6, "state": "completed"}])
    assert (k1, t1) == (k2, t2), (t1, t2)
    free = {"state": "queued", "starts_in_s": 0.0, "starts_in_estimate": "nothing holds"}
    assert "its place in the queue is not known" in scan_report.queued_line(7, free, [])[1]
    assert "next in the queue" in scan_report.queued_line(
        7, {**free, "queue_position": 0}, [])[1]


def test_write_output_never_replaces_a_file_unless_asked(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A result is written whole under its name, or not at all; a file already there (one
    that appeared after the start's check) is kept unless overwrite is given, also on a file
    system without hard links; no part file is left either way."""
    import errno
    import os

    from gonio.cli.scan_report import write_output

    out = tmp_path / "sub" / "felt.h5"
    write_output(out, b"first", overwrite=False)
    assert out.read_bytes() == b"first"
    umask = os.umask(0)
    os.umask(umask)
    assert out.stat().st_mode & 0o777 == 0o666 & ~umask  # not the temporary file's 0600
    with pytest.raises(FileExistsError):
        write_output(out, b"second", overwrite=False)
    assert out.read_bytes() == b"first"
    write_output(out, b"third", overwrite=True)
    assert out.read_bytes() == b"third"
    # A link to nothing is a taken name too (the move would replace the link).
    dangling = tmp_path / "sub" / "link.h5"
    dangling.symlink_to(tmp_path / "nowhere.h5")
    with pytest.raises(FileExistsError):
        write_output(dangling, b"x", overwrite=False)
    assert dangling.is_symlink() and not (tmp_path / "nowhere.h5").exists()

    def no_links(src: object, dst: object) -> None:
        raise OSError(errno.EPERM, "hard links not supported here")

    monkeypatch.setattr(os, "link", no_links)
    with pytest.raises(FileExistsError):
        write_output(out, b"fourth", overwrite=False)
    assert out.read_bytes() == b"third"
    other = tmp_path / "sub" / "linen.h5"
    write_output(other, b"fifth", overwrite=False)
    assert other.read_bytes() == b"fifth"
    assert sorted(p.name for p in (tmp_path / "sub").iterdir()) == ["felt.h5", "linen.h5",
                                                                   "link.h5"]


def test_a_queued_job_followed_asks_only_for_the_jobs_holding_the_rig(
        capsys: pytest.CaptureFixture[str]) -> None:
    """``gonio jobs --daemon URL wait`` on a queued job asked for the daemon's whole job list
    at every half-second poll, for the one line naming the job holding the rig: slow on a
    store of thousands of jobs. It now asks for the jobs in each rig-holding state (the API's
    ``?state=`` filter); the line still names the holder. A scripted client below the HTTP
    boundary records the requests; the real daemon's lines: test_cli_daemon_wait.py."""
    from gonio.cli.daemon_jobs import _follow

    store = [{"id": 4, "state": "completed"}, {"id": 5, "state": "running"},
             *({"id": i, "state": "queued"} for i in range(6, 3000))]
    details = iter([{"state": "queued", "waiting": None, "queue_position": 0,
                     "starts_in_s": None, "starts_in_estimate": None},
                    {"state": "queued", "waiting": None, "queue_position": 0,
                     "starts_in_s": None, "starts_in_estimate": None},
                    {"state": "completed", "done_angles": 2, "total_angles": 2}])
    asked: list[tuple[str, dict[str, Any]]] = []

    class Scripted:
        def request(self, method: str, path: str, **kwargs: Any) -> Any:
            asked.append((path, kwargs.get("params") or {}))
            if path == "/api/v1/jobs/7":
                return next(details)
            assert path == "/api/v1/jobs", path
            state = (kwargs.get("params") or {}).get("state")
            return [j for j in store if state is None or j["state"] == state]

    assert _follow(Scripted(), 7, disabled=True, poll_s=0.0)["state"] == "completed"
    lists = [params for path, params in asked if path == "/api/v1/jobs"]
    assert lists and all(p.get("state") in ("running", "paused", "suspended", "reconstructing")
                         for p in lists), lists
    assert "job 7 queued: waits for job 5 (running) to end" in capsys.readouterr().err


def test_a_queued_job_that_will_be_refused_says_so_in_the_terminal() -> None:
    """The job list's start_refusal (a scan the worker will refuse at its start) is said by
    ``gonio jobs --daemon URL wait`` at the end of its queued line (and again when it comes
    or goes) and by ``show``; it was said nowhere until the job failed."""
    from gonio.cli.jobs_command import detail_lines

    refusal = ("would be refused when it starts, as the queue stands: it reads at exposure "
               "0.02 s and the "
               "calibration in effect was measured at 0.01 s")
    row = {"state": "queued", "waiting": None, "queue_position": 0, "starts_in_s": 0.0,
           "starts_in_bound": False, "starts_in_estimate": "the rig is free"}
    key, text = scan_report.queued_line(7, {**row, "start_refusal": refusal}, [])
    assert text.endswith(f"; {refusal}"), text
    assert scan_report.queued_line(7, row, [])[0] != key
    detail = {**row, "start_refusal": refusal, "id": 7, "kind": "uniform", "specimen": "felt",
              "done_angles": 0, "total_angles": 8, "priority": 0, "created": 0.0,
              "started": None, "finished": None}
    assert f"  {refusal}" in detail_lines(detail)


def test_ordinals_follow_english_usage() -> None:
    """``gonio jobs --daemon URL reorder`` says where the job now stands ("3rd in the
    queue"); the teens take "th" (11th, 12th, 13th), as style guides write them."""
    from gonio.cli.daemon_jobs import ordinal

    assert [ordinal(n) for n in (1, 2, 3, 4, 11, 12, 13, 21, 22, 23, 101, 111, 112)] == [
        "1st", "2nd", "3rd", "4th", "11th", "12th", "13th", "21st", "22nd", "23rd", "101st",
        "111th", "112th"]


def test_a_sim_job_resumes_on_its_own_material_whatever_ran_since(tmp_path: Path) -> None:
    """The material is kept per job: a scan of another plan on another material run since
    (a new job) does not make the interrupted one's material the other's, which the refusal
    then advised, joining two materials in one result. A job interrupted while
    reconstructing measures nothing more: it resumes whatever the material."""
    from types import SimpleNamespace

    from gonio.cli import UsageError
    from gonio.cli.scan_commands import _record_sim_material, _same_sim_material
    from gonio.jobstates import JobState

    db = tmp_path / "gonio.sqlite"
    _record_sim_material(tmp_path, 1, None)  # P1, the default material, interrupted
    _record_sim_material(tmp_path, 2, "pile-000")  # P2 since, another material
    p1 = SimpleNamespace(id=1, state=JobState.PAUSED, done_angles=18, total_angles=32)
    _same_sim_material(tmp_path, p1, None, db)  # its own: resumes
    with pytest.raises(UsageError, match="job 1 was measuring the default material") as e:
        _same_sim_material(tmp_path, p1, "pile-000", db)
    assert "Run the same command without --material to finish it" in str(e.value)
    assert f"gonio jobs abort 1 --db {db}" in str(e.value)
    finishing = SimpleNamespace(id=1, state=JobState.RECONSTRUCTING, done_angles=32,
                                total_angles=32)
    _same_sim_material(tmp_path, finishing, "pile-000", db)
    # A job no run recorded (an older gonio's): as before, it resumes.
    _same_sim_material(tmp_path, SimpleNamespace(id=7, state=JobState.PAUSED, done_angles=1,
                                                 total_angles=8), "pile-000", db)
