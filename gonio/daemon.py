"""Daemon configuration: where to listen, who may change things, where data lives.

A daemon config is a small TOML file (``deploy/daemon.example.toml`` is a complete example)::

    [server]
    host = "127.0.0.1"      # loopback only unless you mean it
    port = 8600
    [auth]
    keys_file = "api-keys"  # one "name key" per line; relative paths are relative to this file
    read_requires_key = false
    [limits]
    max_body_bytes = 1048576
    design_time_limit_s = 60   # longest sampling-design search a request may ask for
    anonymous_requests_per_s = 20  # per address without a key; more get 429 (0 = no limit)
    anonymous_burst = 40
    [paths]
    data_dir = "/var/lib/gonio"
    rig_config = "/etc/gonio/rig.toml"

API keys come from the keys file and from the environment variable ``GONIO_API_KEYS``
(``name:key`` entries separated by commas), so a systemd ``EnvironmentFile=`` or a container
secret can supply them without a file in the config directory. Key values are never logged;
only their names are.
"""

from __future__ import annotations

import contextlib
import ipaddress
import logging
import os
import signal
import stat
import threading
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

from pydantic import ConfigDict, Field, ValidationError

from gonio.apikeys import KEYS_ENV, ApiKeyring, KeyringError, parse_keys_env, parse_keys_file
from gonio.config import DAEMON_TABLES, NumbersNotText, read_toml
from gonio.paths import STORE_NAME
from gonio.wording import counted

if TYPE_CHECKING:
    from gonio.basis_supply import BasisSupply

log = logging.getLogger("gonio.daemon")

DEFAULT_HOST = "127.0.0.1"
DEFAULT_PORT = 8600


class DaemonConfigError(ValueError):
    """The daemon configuration or keys file is invalid; the message says where and what to do."""


class _Section(NumbersNotText):
    model_config = ConfigDict(extra="forbid", frozen=True)


class ServerSection(_Section):
    """``[server]``: the listening socket."""

    host: Annotated[str, Field(min_length=1)] = DEFAULT_HOST
    port: Annotated[int, Field(ge=0, le=65535)] = DEFAULT_PORT
    log_level: Annotated[str, Field(pattern="^(critical|error|warning|info|debug)$")] = "info"


class AuthSection(_Section):
    """``[auth]``: API keys and whether reads need one."""

    keys_file: Path | None = None
    read_requires_key: bool = False


class LimitsSection(_Section):
    """``[limits]``."""

    max_body_bytes: Annotated[int, Field(ge=1024, le=64 << 20)] = 1 << 20
    # A design request occupies a CPU core for up to this long; one runs at a time.
    design_time_limit_s: Annotated[float, Field(gt=0, le=600)] = 60.0
    # Clients without a key, per address: average requests per second (0 = no limit) and how
    # many at once; beyond that 429 with Retry-After (gonio/api/ratelimit.py).
    anonymous_requests_per_s: Annotated[float, Field(ge=0, le=100_000)] = 20.0
    anonymous_burst: Annotated[int, Field(ge=1, le=1_000_000)] = 40


class PathsSection(_Section):
    """``[paths]``: the data directory (jobs database, result files) and the rig config.

    Without ``data_dir`` the daemon uses the rig's own data directory in the user data folder
    (:func:`gonio.paths.scan_data_dir`), the one ``gonio scan`` uses on the same rig config: a
    calibration measured with ``gonio scan --white-reference`` is the one the daemon applies.
    """

    data_dir: Path | None = None
    rig_config: Path | None = None


class ResultsSection(_Section):
    """``[results]``: what a finished scan's result file holds.

    ``export_fits``: fit the export models (factored and principled, judged by rendering)
    when a scan finishes, so exports are immediate. Several seconds of CPU per scan; with
    ``false`` scans finish sooner and each export fits when it is made (docs/export.md).
    """

    export_fits: bool = True


class DaemonConfig(_Section):
    """A whole daemon config file, validated; paths are absolute after loading."""

    server: ServerSection = ServerSection()
    auth: AuthSection = AuthSection()
    limits: LimitsSection = LimitsSection()
    paths: PathsSection = PathsSection()
    results: ResultsSection = ResultsSection()

    def for_rig(self, rig_config: Any) -> DaemonConfig:
        """This config with its data directory settled: ``[paths] data_dir`` if given, else the
        rig's own data directory (:func:`gonio.paths.scan_data_dir`)."""
        if self.paths.data_dir is not None:
            return self
        from gonio.paths import scan_data_dir

        return self.with_overrides(paths__data_dir=str(scan_data_dir(rig_config)))

    def with_overrides(self, **changes: Any) -> DaemonConfig:
        """A copy with ``section__key=value`` overrides (CLI flags), re-validated.

        ``None`` values are ignored, so unset flags keep the file's value.
        """
        data = self.model_dump()
        for dotted, value in changes.items():
            if value is None:
                continue
            section, key = dotted.split("__", 1)
            data[section][key] = value
        return _validate(data, "command line")


def _describe(err: Mapping[str, Any]) -> str:
    loc = ".".join(str(p) for p in err["loc"])
    if err["type"] == "extra_forbidden":
        return f"unknown key {loc!r}; the keys are described in deploy/daemon.example.toml"
    if err["type"] == "missing":
        return f"{loc}: required key is missing"
    if err["type"] == "value_error":
        # A validator's own sentence (it names the value): without pydantic's prefix.
        return f"{loc}: {str(err['msg']).removeprefix('Value error, ')}"
    return f"{loc}: {err['msg']} (got {err.get('input')!r})"


#: Top-level tables only a rig config has (deploy/rig.example.toml).
_RIG_TABLES = frozenset({"rig", "stage", "lights", "sensors", "pairs", "calibration"})


def _validate(data: Mapping[str, Any], source: str) -> DaemonConfig:
    rig_tables = sorted(_RIG_TABLES & data.keys())
    if rig_tables and not DAEMON_TABLES & data.keys():
        # The rig config passed where the daemon config belongs: one line that says so beats
        # an "unknown key" for each of its tables.
        tables = ", ".join(f"[{t}]" for t in rig_tables)
        raise DaemonConfigError(
            f"{source}: a rig config ({tables}), not a daemon config: give it as --rig "
            f"{source}, or name it in the daemon config's [paths] rig_config "
            "(deploy/daemon.example.toml)")
    try:
        return DaemonConfig.model_validate(data)
    except ValidationError as exc:
        lines = [f"{source}: {_describe(e)}" for e in exc.errors()]
        raise DaemonConfigError("\n".join(lines)) from None


def load_daemon_config(path: str | os.PathLike[str] | None) -> DaemonConfig:
    """Read a daemon config file (or the defaults when ``path`` is None).

    Relative paths inside the file are resolved against the file's directory, so a config and
    its keys file can be moved together; without a file they are relative to the working
    directory.

    Raises
    ------
    DaemonConfigError
        The file is missing, not TOML, or has unknown keys or bad values.
    """
    if path is None:
        cfg = DaemonConfig()
        base = Path.cwd()
    else:
        p = Path(path)
        data = read_toml(p, noun="daemon config", example="deploy/daemon.example.toml",
                         error=DaemonConfigError)
        cfg = _validate(data, p.name)
        base = p.resolve().parent

    def absolute(q: Path | None) -> Path | None:
        return None if q is None else (q if q.is_absolute() else base / q)

    return cfg.model_copy(
        update={
            "auth": cfg.auth.model_copy(update={"keys_file": absolute(cfg.auth.keys_file)}),
            "paths": cfg.paths.model_copy(
                update={
                    "data_dir": absolute(cfg.paths.data_dir),
                    "rig_config": absolute(cfg.paths.rig_config),
                }
            ),
        }
    )


def load_keyring(cfg: DaemonConfig, environ: Mapping[str, str] | None = None) -> ApiKeyring:
    """All API keys of the daemon: the keys file plus ``GONIO_API_KEYS``.

    A keys file readable by other users is accepted with a warning (a lab PC is often shared;
    refusing to start would be worse than telling).

    Raises
    ------
    DaemonConfigError
        The keys file is missing or malformed, a name repeats, or a key is too short.
    """
    env = os.environ if environ is None else environ
    keys: dict[str, str] = {}
    path = cfg.auth.keys_file
    # The parsers and the keyring say what is wrong as KeyringError; to the daemon that is
    # a configuration error like any other.
    try:
        if path is not None:
            try:
                text = path.read_text(encoding="utf-8")
            except FileNotFoundError:
                raise DaemonConfigError(
                    f"{path}: API keys file not found; create it with one 'name key' line per "
                    "user (see docs/install.md) or remove [auth] keys_file from the daemon config"
                ) from None
            except OSError as exc:
                raise DaemonConfigError(
                    f"{path}: cannot read the API keys file: {exc.strerror}"
                ) from None
            if path.stat().st_mode & (stat.S_IRGRP | stat.S_IROTH):
                log.warning("API keys file %s is readable by other users; chmod 600 it", path)
            keys.update(parse_keys_file(text, str(path)))
        for name, key in parse_keys_env(env.get(KEYS_ENV, "")).items():
            if name in keys:
                raise DaemonConfigError(
                    f"{KEYS_ENV}: key name {name!r} is also in the keys file; use distinct names"
                )
            keys[name] = key
        return ApiKeyring(keys)
    except KeyringError as exc:
        raise DaemonConfigError(str(exc)) from None


# --------------------------------------------------------------------------- wiring
STORE_FILE = STORE_NAME  # gonio.sqlite, where `gonio jobs` also looks (gonio.paths)


def api_settings(cfg: DaemonConfig, keyring: ApiKeyring) -> Any:
    """The HTTP layer's settings for ``cfg`` (imported lazily: FastAPI is not needed to parse)."""
    from gonio.api.auth import AccessPolicy
    from gonio.api.settings import ApiSettings

    assert cfg.paths.data_dir is not None, "settle the data directory first (for_rig)"
    return ApiSettings(
        access=AccessPolicy(keyring, read_requires_key=cfg.auth.read_requires_key),
        data_dir=cfg.paths.data_dir,
        max_body_bytes=cfg.limits.max_body_bytes,
        design_time_limit_s=cfg.limits.design_time_limit_s,
        anonymous_rate_per_s=cfg.limits.anonymous_requests_per_s,
        anonymous_burst=cfg.limits.anonymous_burst,
    )


def build_app(
    cfg: DaemonConfig,
    rig_config: Any,
    keyring: ApiKeyring,
    *,
    basis: BasisSupply | None = None,
    rig: Any = None,
) -> Any:
    """The daemon's ASGI app: store in ``data_dir``, real drivers for ``rig_config``.

    Parameters
    ----------
    cfg : DaemonConfig
    rig_config : gonio.config.RigConfig
    keyring : ApiKeyring
    basis : BasisSupply, optional
        The reconstruction basis of this daemon; default: the default basis, loaded (or built)
        once on first use and shared by the service, its worker and finishing.
    rig : gonio.hal.Rig, optional
        Use this rig instead of building drivers from ``rig_config`` (tests, custom rigs).

    Returns
    -------
    FastAPI app whose lifespan starts and stops the service (worker, devices).
    """
    from gonio.api.app import create_app
    from gonio.basis_supply import BasisSupply
    from gonio.drivers.factory import build_rig
    from gonio.locks import DATA_DIR_ELSEWHERE, claim_endpoints, claim_store
    from gonio.service import GonioService
    from gonio.store import JobStore

    cfg = cfg.for_rig(rig_config)
    assert cfg.paths.data_dir is not None  # for_rig settled it
    data_dir = cfg.paths.data_dir.absolute()
    data_dir.mkdir(parents=True, exist_ok=True)
    # One daemon per data directory and one owner per rig, for this process's life: refused
    # here (LockBusy naming the holder) before anything is opened or served.
    owned: list[Any] = [claim_store(data_dir / STORE_FILE, f"data directory {data_dir}",
                                    DATA_DIR_ELSEWHERE)]
    try:
        endpoints = getattr(rig_config, "endpoints", None)
        if endpoints is not None:
            owned.append(claim_endpoints(endpoints()))
        store = JobStore(data_dir / STORE_FILE)
        service = GonioService(
            store,
            rig if rig is not None else (lambda: build_rig(rig_config)),
            rig_config=rig_config,
            basis=basis if basis is not None else BasisSupply(),
            data_dir=data_dir,
            fit_exports=cfg.results.export_fits,
        )
        # State files are checked before anything is served (docs/engine.md, "State files
        # at start"): the store by JobStore itself (quick_check), the calibration here (a
        # damaged or implausible one refuses the start, naming the file); a damaged result
        # file costs only its own job, so it is reported, and refused when asked for.
        service.calibration()
        for line in service.damaged_results():
            log.warning("result file check: %s", line)
    except BaseException:
        for lock in reversed(owned):
            lock.release()
        raise
    service.owned = owned
    log_job_events(service)
    return create_app(service, api_settings(cfg, keyring))


def is_loopback_host(host: str) -> bool:
    """Whether binding ``host`` keeps the daemon to this machine: ``localhost`` or a loopback
    address (``127.0.0.0/8``, ``::1``, or either IPv4-mapped). Anything else may be reachable
    by others: ``0.0.0.0``/``::`` (every interface), a LAN address, a host name (it may
    resolve to any of these)."""
    name = host.strip().strip("[]")
    if name.lower() == "localhost":
        return True
    try:
        addr = ipaddress.ip_address(name.split("%", 1)[0])  # an IPv6 zone (%eth0) is no address
    except ValueError:
        return False
    mapped = getattr(addr, "ipv4_mapped", None)
    return bool(addr.is_loopback or (mapped is not None and mapped.is_loopback))


JOB_LOG = logging.getLogger("gonio.jobs")
"""What happened to jobs, one line each, on the daemon's console (instead of every request)."""


def log_job_events(service: Any) -> None:
    """Log each job's start, pause, resumption, end and an applied calibration to
    :data:`JOB_LOG`, from the job store's events (the same ones the API streams)."""

    def on_event(ev: Any) -> None:
        if ev.job_id is None or ev.type not in ("state", "recovered"):
            return
        # Runs in the committing thread: a log line must never break the commit it reports.
        try:
            row = service.store.get_job(ev.job_id)
            level, line = job_event_line(ev.type, ev.data, row, service)
        except Exception:  # e.g. removed meanwhile
            JOB_LOG.debug("no log line for event %s of job %s", ev.type, ev.job_id,
                          exc_info=True)
            return
        if line:
            JOB_LOG.log(level, "%s", line)

    service.add_event_listener(on_event)


def job_event_line(type_: str, data: Mapping[str, Any], row: Any,
                   service: Any) -> tuple[int, str | None]:
    """(log level, line) for one job event; None for events not worth a line.

    Parameters
    ----------
    type_ : the event type (``state`` or ``recovered``)
    data : the event's data (``from``, ``state``, ``reason``, ``note`` ...)
    row : the job's :class:`gonio.store.JobRow` after the event
    """
    job = f"job {row.id} ({row.kind}, {row.specimen!r})"
    angles = f"{row.done_angles} of {row.total_angles} angles"
    reason = f": {data['reason']}" if data.get("reason") else ""
    if type_ == "recovered":
        found = data.get("state")
        # What happens next depends on the state: a paused job waits for the user, and the
        # queue behind it waits too.
        then = {"paused": f"stays paused until resumed (the page's resume, gonio jobs "
                          f"--daemon URL resume {row.id}, or POST "
                          f"/api/v1/jobs/{row.id}/resume); queued jobs wait behind it",
                "reconstructing": "its reconstruction starts again from the stored readings",
                }.get(str(found), "resumes from its checkpoint")
        return logging.INFO, f"{job} found {found} at start ({angles}): {then}"
    state, before = data.get("state"), data.get("from")
    if state == "running":
        if before == "queued":
            # The plan's stage angles (the job's own steps are laid out just after this).
            n = row.total_angles or row.plan.get("rotations") or row.plan.get(
                "initial_rotations")
            return logging.INFO, f"{job} started" + (f": {counted(n, 'stage angle')}" if n else "")
        return logging.INFO, f"{job} resumed from {before} ({angles})"
    if state in ("paused", "suspended"):
        level = logging.WARNING if state == "suspended" else logging.INFO
        return level, f"{job} {state} ({angles}){reason}"
    if state == "reconstructing":
        # A calibration reconstructs nothing: it factors its readings into the calibration.
        then = "computing the calibration" if row.kind == "calibration" else "reconstructing"
        return logging.INFO, f"{job} measured {angles}; {then}"
    if state == "completed":
        if row.kind == "calibration":
            cal = service.calibration()
            return logging.INFO, (f"{job} completed: calibration applied ({cal.source}, "
                                  f"{counted(len(cal.pairs), 'pair')}): later scans are in 1/sr")
        from gonio.figures import headline_error

        summary = row.summary or {}
        err = headline_error(summary)
        units = "in 1/sr" if summary.get("calibrated") else "UNCALIBRATED (sensor units)"
        return logging.INFO, (f"{job} completed, {units}: "
                              + (f"{err['key']} {err['text']}" if err else "no error estimate")
                              + (f"; result {row.result_path}" if row.result_path else ""))
    if state in ("failed", "aborted", "halted"):
        level = logging.INFO if state == "aborted" else logging.ERROR
        return level, f"{job} {state} ({angles}){reason}"
    return logging.DEBUG, None


def warn_if_exposed(cfg: DaemonConfig, keyring: ApiKeyring) -> None:
    """Log what a non-loopback bind means, so an exposed daemon is a decision, not an accident."""
    if not is_loopback_host(cfg.server.host):
        log.warning(
            "listening on %s: every machine that can reach this address can read the rig "
            "status%s", cfg.server.host,
            "" if cfg.auth.read_requires_key else " and results (set [auth] read_requires_key)",
        )
    if len(keyring) == 0:
        log.warning("no API keys configured: the daemon is read-only (see docs/install.md)")
    else:
        log.info("API keys loaded: %s", ", ".join(keyring.names))


def serve(app: Any, cfg: DaemonConfig, on_started: Any = None) -> int:
    """Run ``app`` with uvicorn on ``cfg.server`` until interrupted (SIGINT/SIGTERM).

    ``on_started(url, stop)`` is called once the socket listens (the CLI prints the address
    there); calling ``stop()`` from any thread shuts the server down gracefully. Ctrl-C does the
    same and returns normally.

    Returns
    -------
    int
        The process exit status: 0 after a requested stop, 1 when the daemon stopped because
        its job worker died (so a supervisor restarts it).
    """
    import uvicorn

    from gonio.heap import bound_heap

    bound_heap()  # the daemon's size levels off after its first scan (gonio/heap.py)
    config = uvicorn.Config(
        app,
        host=cfg.server.host,
        port=cfg.server.port,
        log_level=cfg.server.log_level,
        # Event streams never end by themselves: give them 3 s to close on shutdown.
        timeout_graceful_shutdown=3,
        # Keys travel in headers, which uvicorn never logs; query strings are logged, which is
        # why the API does not accept keys there.
        access_log=cfg.server.log_level in ("info", "debug"),
    )
    server = uvicorn.Server(config)
    # After uvicorn has configured its loggers: keys in query strings never reach the access
    # log, and pymodbus' raw frame dumps are not errors of the daemon.
    from gonio import logfilters

    logfilters.install(quiet_reads=cfg.server.log_level != "debug")
    closer = getattr(getattr(app, "state", None), "stream_closer", None)
    original_handle_exit = server.handle_exit

    def handle_exit(sig: int, frame: Any) -> None:
        # Ctrl-C / SIGTERM: end the event streams first, so the graceful shutdown has no open
        # response to wait for (it would wait its whole timeout, then cancel them).
        if closer is not None:
            closer.close()
        original_handle_exit(sig, frame)

    server.handle_exit = handle_exit  # type: ignore[method-assign]
    if on_started is not None:
        original = server.startup

        async def startup(sockets: Any = None) -> None:
            await original(sockets=sockets)
            if server.started:
                for s in server.servers:
                    for sock in s.sockets:
                        host, port = sock.getsockname()[:2]
                        url = f"http://{_url_host(host)}:{port}/"
                        from gonio.locks import advertise_url

                        # A program refused by this daemon's locks is told this address.
                        advertise_url(url)
                        on_started(url, stop)
                        return

        server.startup = startup  # type: ignore[method-assign]

    def stop() -> None:
        if closer is not None:
            closer.close()
        server.should_exit = True

    service = getattr(app.state, "service", None) if hasattr(app, "state") else None
    if service is not None:
        service.on_fatal = stop
    # uvicorn re-raises the signal that stopped it after its graceful shutdown; by then
    # everything is closed. Ctrl-C arrives as KeyboardInterrupt; SIGTERM's default action
    # would end the process on the spot, skipping every cleanup of the callers (`serve --sim`
    # deletes its temporary rig folder on the way out), so it is raised as an exception too.
    previous = _terminate_by_exception()
    try:
        with contextlib.suppress(KeyboardInterrupt, Terminated):
            server.run()
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)
    if service is not None and service.worker_failure is not None:
        log.critical("exiting with status 1: the job worker died (%s)", service.worker_failure)
        return 1
    return 0


class Terminated(Exception):
    """SIGTERM arrived: the process unwinds (running its cleanups) instead of dying."""


def _raise_terminated(_sig: int, _frame: Any) -> None:
    raise Terminated


def _terminate_by_exception() -> Any:
    """Make SIGTERM raise :class:`Terminated` in the main thread; returns the handler it
    replaced (None off the main thread, where signals cannot be handled)."""
    if threading.current_thread() is not threading.main_thread():
        return None
    return signal.signal(signal.SIGTERM, _raise_terminated)


def _url_host(host: str) -> str:
    if host in ("0.0.0.0", "::"):
        return "127.0.0.1"
    return f"[{host}]" if ":" in host else host
