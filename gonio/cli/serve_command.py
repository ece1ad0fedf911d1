"""``gonio serve``: run the daemon (REST API, live events, lab page) on a rig.

Two ways to run it:

* ``gonio serve --config daemon.toml [--rig rig.toml]``: the lab PC (see docs/install.md);
* ``gonio serve --sim``: a simulated rig started in this process, and the daemon on it. Prints
  the address to open, with the session's API key in the address's ``#fragment`` (browsers
  never send the fragment to the server, so the key does not reach any log); the key is kept
  in the data directory (:func:`gonio.cli.sim_session.session_key`), so an open page keeps
  working across restarts. ``--demo-scan`` also
  runs one scan through the HTTP API, prints its progress and result, and exits (smoke test).

What is on the simulated stage is part of the rig's state and follows the jobs, as a person
at a real rig would: before a job measures (new or resumed after a restart), a calibration job
gets the white reference and any other job the specimen. At start-up, when no calibration is
in effect (none in the data directory, none queued or unfinished there), a calibration job is
queued first; every scan afterwards is in 1/sr. A restart on the same data directory resumes
an interrupted scan on its specimen and calibrates nothing again.

Data live in the user data folder (:func:`gonio.paths.sim_daemon_data_dir`, printed at start)
unless ``--data-dir`` names one; ``--throwaway`` uses a temporary folder deleted at exit.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import threading
from pathlib import Path
from typing import Any

from gonio.cli import UsageError, positive_float
from gonio.cli.daemon_client import API_KEY_ENV
from gonio.wording import counted

DEMO_ROTATIONS = 8


def register(subparsers: Any) -> None:
    """Add the ``serve`` sub-command."""
    p = subparsers.add_parser(
        "serve",
        help="run the daemon: REST API, live events and the lab web page",
        description=(
            "Run the gonio daemon on a rig. With --sim, start a simulated rig in this process "
            "and serve it; open the printed address and start a scan from the page."
        ),
    )
    p.add_argument("--config", type=Path, default=None, metavar="DAEMON_TOML",
                   help="daemon config (see deploy/daemon.example.toml); default: built-in "
                   "defaults (127.0.0.1:8600, no keys)")
    p.add_argument("--rig", type=Path, default=None, metavar="RIG_TOML",
                   help="rig config; overrides [paths] rig_config of the daemon config")
    p.add_argument("--host", default=None, help="address to bind (default 127.0.0.1)")
    p.add_argument("--port", type=int, default=None, help="port (default 8600; 0 = any free)")
    p.add_argument("--keys-file", type=Path, default=None, metavar="FILE",
                   help="API keys file (from gonio keys new); overrides [auth] keys_file")
    p.add_argument("--data-dir", type=Path, default=None,
                   help="jobs database and results (with --sim, default: the user data "
                   "folder's serve-sim/, printed at start)")
    p.add_argument("--no-export-fits", action="store_true",
                   help="scans finish without the export fits (several seconds of CPU "
                   "sooner; each export fits when it is made); sets [results] export_fits "
                   "= false")
    sim = p.add_argument_group("simulated rig (--sim)")
    sim.add_argument("--sim", action="store_true",
                     help="start a simulated rig in this process and serve it")
    sim.add_argument("--stage", choices=("dynamixel", "zaber"), default="dynamixel",
                     help="simulated stage protocol (default dynamixel)")
    sim.add_argument("--material", default=None,
                     help="library material name, .npz BRDF table, or a spectral material "
                     "read by 31-band sensors (solid-red-paint, metallic-blue-paint, ...: "
                     "docs/colour.md) for the specimen")
    sim.add_argument("--time-scale", type=positive_float, default=1.0,
                     help="sim seconds per wall second for motion and exposures")
    sim.add_argument("--modbus-port", type=int, default=0, metavar="PORT",
                     help="TCP port of the simulated Modbus lights and sensors on 127.0.0.1 "
                     "(default 0: any free port; choose one where a firewall allows only "
                     "known ports)")
    sim.add_argument("--throwaway", action="store_true",
                     help="keep jobs and results in a temporary folder deleted at exit")
    sim.add_argument("--demo-scan", action="store_true",
                     help=f"run one {DEMO_ROTATIONS}-angle scan through the API, print the result "
                     "and exit (exit code 0 when it completed)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from gonio.heap import bound_heap

    bound_heap()  # before the simulated rig's threads allocate (gonio/heap.py)
    from gonio.daemon import (
        DaemonConfigError,
        build_app,
        load_daemon_config,
        load_keyring,
        serve,
        warn_if_exposed,
    )

    if args.port is not None and not 0 <= args.port <= 65535:
        raise UsageError(f"--port {args.port}: use 0 to 65535")
    if not args.sim and (args.demo_scan or args.material is not None or args.throwaway):
        raise UsageError("--demo-scan, --material and --throwaway need --sim (they drive the "
                         "simulated rig)")
    if args.throwaway and args.data_dir is not None:
        raise UsageError("--throwaway and --data-dir exclude each other: a throwaway run keeps "
                         "nothing")
    try:
        cfg = load_daemon_config(args.config)
        cfg = cfg.with_overrides(
            server__host=args.host, server__port=args.port,
            paths__data_dir=str(args.data_dir) if args.data_dir is not None else None,
            paths__rig_config=str(args.rig) if args.rig is not None else None,
            auth__keys_file=str(args.keys_file) if args.keys_file is not None else None,
            results__export_fits=False if args.no_export_fits else None,
        )
        keyring = load_keyring(cfg)
    except DaemonConfigError as exc:
        raise UsageError(str(exc)) from None
    _check_port_free(cfg.server.host, cfg.server.port)
    _configure_logging(cfg.server.log_level)

    if not args.sim:
        from gonio.config import load_rig_config

        if cfg.paths.rig_config is None:
            raise UsageError(
                "no rig config: give --rig rig.toml or set [paths] rig_config in the daemon "
                "config (start from deploy/rig.example.toml), or try --sim"
            )
        rig_config = load_rig_config(cfg.paths.rig_config)
        # The rig's own data directory unless one is configured: the one `gonio scan` on the
        # same rig config uses, so its calibration is the daemon's too.
        cfg = cfg.for_rig(rig_config)
        assert cfg.paths.data_dir is not None
        data_dir = cfg.paths.data_dir.resolve()
        warn_if_exposed(cfg, keyring)
        app = _build(build_app, cfg, rig_config, keyring)
        from gonio.cli.sim_session import sim_specimen_truth

        # A rig `gonio sim` runs: results record the simulated material (renderings' truth).
        truth = sim_specimen_truth(Path(str(cfg.paths.rig_config)), rig_config)
        if truth is not None:
            app.state.service.specimen_truth = lambda: truth

        def started(url: str, _stop: Any) -> None:
            # Say where jobs and results go, and whether scans will be calibrated.
            print(f"data directory {data_dir} (job store, results, calibration)")
            print(f"calibration: {_calibration_line(app.state.service)}")
            print(f"gonio serving on {url}", flush=True)

        return serve(app, cfg, on_started=started)
    return _run_sim(args, cfg, keyring)


def _check_port_free(host: str, port: int) -> None:
    """Refuse to start, saying what to do, when ``host:port`` is taken (another daemon, or any
    program): uvicorn would start the service (and a simulated rig) first, then stop with
    "[Errno 98] ... address already in use" and exit status 3. Binds as uvicorn does
    (``SO_REUSEADDR``), then lets go; port 0 (any free port) is never taken."""
    import errno
    import socket

    if port == 0:
        return
    try:
        infos = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM)
    except OSError:
        return  # a host that does not resolve: uvicorn says so
    family, kind, proto, _, address = infos[0]
    with socket.socket(family, kind, proto) as sock:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            sock.bind(address)
        except OSError as exc:
            if exc.errno != errno.EADDRINUSE:
                return  # not ours to judge (permissions ...): uvicorn reports it
            where = f"[{host}]" if ":" in host else host  # an IPv6 address in a URL
            raise UsageError(
                f"cannot start: port {port} on {host} is in use by another program (a gonio "
                f"daemon already running? open http://{where}:{port}/health to see); stop it, "
                "or choose another port with --port N (--port 0: any free port, printed at "
                "start)") from None


def _calibration_line(service: Any) -> str:
    """One line on the calibration the daemon applies (printed at start)."""
    cal = service.calibration()
    if cal.pairs:
        return f"{cal.source}, {counted(len(cal.pairs), 'pair')}: scans are in 1/sr"
    return ("none: scans stay in sensor units until a calibration job completes (a white "
            "reference on the stage: 'gonio scan --daemon URL --white-reference ALBEDO' or "
            "the page's calibration kind)")


def _claim_data_dir(data_dir: Path) -> Any:
    """This process's lock on a daemon data directory (:func:`gonio.locks.claim_store`), or a
    one-line refusal naming the process that has it."""
    from gonio.daemon import STORE_FILE
    from gonio.locks import DATA_DIR_ELSEWHERE, LockBusy, claim_store

    try:
        return claim_store(Path(data_dir) / STORE_FILE, f"data directory {data_dir}",
                           DATA_DIR_ELSEWHERE)
    except LockBusy as exc:
        raise UsageError(f"cannot start: {exc}") from None


def _build(build_app: Any, *args: Any) -> Any:
    """``build_app(*args)``, with a data directory or rig owned by another process reported
    as one line naming that process (exit status 2) rather than a traceback."""
    from gonio.locks import LockBusy

    try:
        return build_app(*args)
    except LockBusy as exc:
        raise UsageError(f"cannot start: {exc}") from None


def _configure_logging(level: str) -> None:
    import logging

    logging.basicConfig(
        level=level.upper(), format="%(asctime)s %(levelname)s %(name)s: %(message)s"
    )
    # At INFO, httpx logs every request of the --demo-scan client and pymodbus every server
    # start: noise next to the daemon's own messages. Their warnings still show.
    for noisy in ("httpx", "pymodbus"):
        logging.getLogger(noisy).setLevel(max(logging.WARNING, logging.getLogger().level))


#: The name of the file in a ``gonio serve --sim`` temporary folder that names its process.
SESSION_PID_FILE = "gonio-serve.pid"
#: The prefix of those folders in the system's temporary directory.
SESSION_PREFIX = "gonio-serve-"


def _remove_stale_sessions(tmp_root: Path | None = None) -> list[Path]:
    """Remove the temporary folders of ``gonio serve --sim`` sessions whose process is gone.

    A session removes its folder (the simulated rig's config; with ``--throwaway`` its whole
    data directory) when it stops, but not when it is killed (``kill -9``, the machine's
    out-of-memory killer): they piled up in the temporary directory. Each folder names its
    process in :data:`SESSION_PID_FILE`; one whose process no longer exists is removed at the
    next start. A folder without that file (an older gonio's, or not yet written) is left.

    Returns
    -------
    list of Path : the folders removed
    """
    import contextlib
    import shutil

    root = Path(tmp_root) if tmp_root is not None else Path(tempfile.gettempdir())
    removed = []
    for folder in root.glob(f"{SESSION_PREFIX}*"):
        marker = folder / SESSION_PID_FILE
        try:
            pid = int(marker.read_text().strip())
        except (OSError, ValueError):
            continue
        if pid == os.getpid() or _process_alive(pid):
            continue
        with contextlib.suppress(OSError):
            shutil.rmtree(folder)
            removed.append(folder)
    return removed


def _process_alive(pid: int) -> bool:
    """Whether process ``pid`` exists (another user's counts: it is not ours to remove)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _run_sim(args: argparse.Namespace, cfg: Any, keyring: Any) -> int:
    from gonio.apikeys import ApiKeyring
    from gonio.cli.sim_session import (
        SESSION_KEY_FILE,
        attach_sim,
        calibration_not_needed,
        start_sim_calibration,
    )
    from gonio.cli.sim_session import session_key as sim_session_key
    from gonio.daemon import build_app, is_loopback_host, serve, warn_if_exposed
    from gonio.sim.rig import WHITE_REFERENCE_ALBEDO, SimRigOptions, start_sim_rig

    if not args.time_scale > 0:
        raise UsageError(f"--time-scale must be > 0, got {args.time_scale}")
    # A newcomer's sim session gets its own key unless keys are configured: one kept in the
    # data directory, so a page left open keeps working across restarts (session_key).
    session_key = None
    _remove_stale_sessions()
    with tempfile.TemporaryDirectory(prefix=SESSION_PREFIX) as tmp:
        # Names this process, so a later start removes the folder if this one is killed.
        (Path(tmp) / SESSION_PID_FILE).write_text(str(os.getpid()))
        if args.throwaway:
            cfg = cfg.with_overrides(paths__data_dir=str(Path(tmp) / "data"))
        elif cfg.paths.data_dir is None:
            from gonio.paths import sim_daemon_data_dir

            cfg = cfg.with_overrides(paths__data_dir=str(sim_daemon_data_dir()))
        data_dir = cfg.paths.data_dir
        assert data_dir is not None  # settled just above
        # Own the data directory before reading or writing anything in it (a second daemon on
        # it is refused here, naming the first); build_app takes the same lock again.
        owned = _claim_data_dir(data_dir)
        key_kept = False
        if len(keyring) == 0:
            session_key, key_kept = sim_session_key(Path(data_dir))
            keyring = ApiKeyring({"sim-session": session_key})
        warn_if_exposed(cfg, keyring)
        material = _sim_material(data_dir, args.material)
        try:
            sim = start_sim_rig(SimRigOptions(
                stage=args.stage, material=material, time_scale=args.time_scale,
                config_path=Path(tmp) / "rig.toml", modbus_port=args.modbus_port,
                # The stage's zero (its Homing Offset) outlives a restart, as on a real servo:
                # a scan resumed after one reads with the zero it started with.
                stage_eeprom=Path(data_dir) / SIM_STAGE_EEPROM,
            ))
        except (ValueError, OSError) as exc:
            owned.release()
            raise UsageError(f"cannot start the simulated rig: {exc}") from None
        with owned, sim:
            app = _build(build_app, cfg, sim.config, keyring)
            # The hand on the stage, and results that record the material on it (renderings
            # show the truth beside the reconstruction).
            attach_sim(app.state.service, sim)
            result: dict[str, int] = {}

            def started(url: str, stop: Any) -> None:
                fragment = f"#key={session_key}" if session_key else ""
                if fragment and not is_loopback_host(cfg.server.host):
                    # The address works from other machines: whoever sees it (a shared
                    # screen, a terminal log) can control the rig with the key in it.
                    _line(f"warning: --host {cfg.server.host} is reachable from other "
                          "machines; the address below holds the session's API key: anyone "
                          "who sees it can control the rig", err=True)
                _line(f"simulated rig {sim.config.rig.name!r}: {len(sim.config.lights)} lights, "
                      f"{len(sim.config.sensors)} sensors; rig config {sim.config_path}")
                kept = ("a temporary folder, deleted at exit" if args.throwaway
                        else "kept across restarts")
                _line(f"data directory {data_dir} ({kept})")
                if key_kept:
                    _line(f"API key: the one of the last start on this data directory (kept in "
                          f"{Path(data_dir) / SESSION_KEY_FILE}; delete it for a new one)")
                _line(f"gonio serving on {url}")
                _line(f"open {url}{fragment} and start a scan (Ctrl-C stops)")
                if session_key:
                    # The key was in the page's address alone: a lab going on from a shell
                    # (gonio scan --daemon, gonio jobs --daemon) was refused and had to pick
                    # it out of the URL.
                    _line(f"from a shell: export {API_KEY_ENV}={session_key}, then e.g. "
                          f"gonio jobs --daemon {url.rstrip('/')} list")
                # Called on the server's event loop, once it listens: the service runs.
                service = app.state.service
                why_not = calibration_not_needed(service)
                if why_not is not None:
                    _line(f"calibration: {why_not}")
                else:
                    job_id = start_sim_calibration(service, sim, report=_print_calibration)
                    _line(f"calibrating the simulated rig: job {job_id} measures a white "
                          f"reference (albedo {WHITE_REFERENCE_ALBEDO:g}), then the specimen "
                          "goes back")
                if args.demo_scan:
                    key = session_key or _first_key_hint()
                    threading.Thread(target=_demo_scan, args=(url, key, result, stop),
                                     daemon=True).start()

            code = serve(app, cfg, on_started=started)
            if args.demo_scan and code == 0:
                job_id = result.get("job_id")
                if job_id is not None and result.get("code") == 0:
                    _line(f"demo scan result file: {data_dir / 'results' / f'job-{job_id}.h5'}"
                          + (" (deleted now: --throwaway)" if args.throwaway else ""))
                return result.get("code", 1)
    return code


SIM_STATE_FILE = "sim-specimen.json"
"""In a ``serve --sim`` data directory: the simulated specimen's material (``--material``)."""

SIM_STAGE_EEPROM = "sim-stage-eeprom.json"
"""In a ``serve --sim`` data directory: the simulated Dynamixel's EEPROM (its Homing Offset,
the stage's zero), kept across restarts as a real servo keeps it across power cycles."""


def _sim_material(data_dir: Path, requested: str | None) -> str | None:
    """The material to simulate: ``requested``, unless an interrupted job in ``data_dir`` was
    measuring another one (then that one, so the job resumes on its own specimen).

    Records the choice in :data:`SIM_STATE_FILE`.
    """
    import json

    from gonio.daemon import STORE_FILE
    from gonio.store import JobStore

    state = data_dir / SIM_STATE_FILE
    material = requested
    if state.is_file() and (data_dir / STORE_FILE).is_file():
        try:
            recorded = json.loads(state.read_text()).get("material")
        except (ValueError, AttributeError):
            recorded = requested
        store = JobStore(data_dir / STORE_FILE, durable=False)
        # A job interrupted while reconstructing measures nothing more, and its finishing
        # records the truth it kept when it began (gonio.finishing): it holds no specimen.
        active = [j for j in store.active_jobs() if j.kind != "calibration"
                  and not (j.state.value == "reconstructing"
                           and "true_material" in (store.finishing_inputs(j.id) or {}))]
        store.close()
        if active and recorded != requested:
            # It said "it stays on the stage until the job ends", but the simulated specimen
            # is chosen once per start: every later scan of this run measured it too.
            print(f"job {active[0].id} was interrupted while measuring material "
                  f"{recorded or 'default'!r}: it stays on the stage so the job resumes on its "
                  f"own specimen, and every scan until this daemon stops measures it too "
                  f"(--material {requested or 'default'!r} applies at the next start once job "
                  f"{active[0].id} has ended)",
                  file=sys.stderr, flush=True)
            material = recorded
    data_dir.mkdir(parents=True, exist_ok=True)
    state.write_text(json.dumps({"material": material}))
    return material


def _line(text: str, *, err: bool = False) -> None:
    """Print ``text`` and its newline in one write, then flush.

    ``serve --sim`` prints from the demo-scan thread and the server's loop while the daemon
    logs from its own threads to the same terminal: ``print`` writes the text and the newline
    separately, and on an unbuffered stream (``python -u``, ``PYTHONUNBUFFERED``) another
    thread's log line could land between them, joined to the text.
    """
    stream = sys.stderr if err else sys.stdout
    stream.write(text + "\n")
    stream.flush()


def _print_calibration(job_id: int, state: str, reason: str | None) -> None:
    if state == "completed":
        _line(f"calibration job {job_id} completed: scans are now in 1/sr")
    else:
        _line(f"calibration job {job_id} {state}" + (f" ({reason})" if reason else "")
              + ": scans stay in sensor counts until a calibration completes", err=True)


def _first_key_hint() -> str:
    import os

    from gonio.apikeys import KEYS_ENV, parse_keys_env

    keys = parse_keys_env(os.environ.get(KEYS_ENV, ""))
    if not keys:
        raise UsageError(f"--demo-scan with configured keys needs one in {KEYS_ENV}")
    return next(iter(keys.values()))


def _demo_scan(url: str, key: str | None, result: dict[str, int], stop: Any) -> None:
    """Submit one scan over HTTP, print its progress from the event stream, then stop.

    The server stops after the scan, so no URL is printed for the result: the caller prints
    the result file's path once the server is down (a throwaway run keeps none).
    """
    import json

    import httpx

    headers = {"X-API-Key": key} if key else {}
    code = 1
    try:
        with httpx.Client(base_url=url, headers=headers, timeout=httpx.Timeout(10, read=None)) as c:
            seq = c.get("/health").json()["seq"]
            plan = {"kind": "uniform", "specimen": "demo", "rotations": DEMO_ROTATIONS}
            r = c.post("/api/v1/jobs", json={"plan": plan})
            if r.status_code != 201:
                _line(f"demo scan refused: {r.status_code} {r.text}", err=True)
                return
            job_id = r.json()["id"]
            result["job_id"] = job_id
            _line(f"demo scan: job {job_id} queued")
            with c.stream("GET", "/api/v1/events", params={"since": seq, "job_id": job_id}) as s:
                for line in s.iter_lines():
                    if not line.startswith("data:"):
                        continue
                    ev = json.loads(line[5:])
                    if ev["type"] == "progress":
                        d = ev["data"]
                        # The specimen's angle (0-360); the stage itself may be turns further.
                        _line(f"  angle {d['done']}/{d['total']}: specimen at "
                              f"{d['actual_deg'] % 360:.2f} deg")
                    elif ev["type"] == "state":
                        state = ev["data"]["state"]
                        _line(f"  job {job_id}: {state}"
                              + (f" ({ev['data']['reason']})" if ev["data"].get("reason") else ""))
                        if state == "reconstructing":
                            _line("  reconstructing (the first run also builds the default "
                                  "basis; later runs reuse it)")
                        if state in ("completed", "failed", "aborted", "halted"):
                            break
            job = c.get(f"/api/v1/jobs/{job_id}").json()
            if job["state"] == "completed":
                m = c.get(f"/api/v1/jobs/{job_id}/metrics").json()
                units = "1/sr (calibrated)" if m.get("calibrated") else "sensor counts"
                # The one error number the page shows too (docs/api.md, headline_error).
                err = m.get("headline_error")
                err_text = f"{err['key']} {err['text']}" if err else "no error estimate"
                _line(f"demo scan completed: {m.get('n_samples')} samples in {units}, "
                      f"{err_text}")
                for part in ("coverage", "interval"):
                    if err and err.get(part):
                        _line(f"  {err[part]}")
                if err and err.get("mirror_gap"):
                    # The rig's layout limits what the estimate can see (docs/api.md).
                    _line(f"  Note: {err['mirror_gap']}.")
                code = 0
    except Exception as exc:  # reported, and the exit code says it failed
        _line(f"demo scan failed: {exc}", err=True)
    finally:
        result["code"] = code
        stop()
