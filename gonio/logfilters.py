"""Log filters of the daemon: what must never reach its output, and what is not an error.

* :class:`QueryKeyRedactor` on uvicorn's access log: a request that puts a key (or token,
  secret, password) in its query string is refused by the API, but the access log would still
  have written the key down. The value is replaced by ``[redacted]``; the parameter name stays,
  so the log still shows what the client did.
* :class:`RoutineRequestFilter` on the access log: successful reads (the page's polls) are
  not logged; changes and refusals are.
* :class:`PymodbusFrameFilter` on pymodbus' logger: pymodbus logs a corrupted or unexpected
  reply at ERROR and appends the last raw frames as hex dumps. The drivers already turn such a
  reply into a device fault that names the device and the cause, so these records become
  WARNINGs of one line (the frames are logged by pymodbus itself at DEBUG level).

:func:`install` attaches them; :func:`gonio.daemon.serve` calls it after uvicorn has
configured its loggers. :func:`install_pymodbus` attaches the pymodbus filter alone, for the
``gonio`` command line (``gonio scan`` and the other commands that talk to a rig).
"""

from __future__ import annotations

import logging
import re
from urllib.parse import parse_qsl, quote

SECRET_PARAM = re.compile(r"(key|token|secret|passw|auth)", re.IGNORECASE)
"""Query parameter names whose values are never logged (``api_key``, ``X-API-Key``, ...)."""

REDACTED = "[redacted]"
ACCESS_LOGGER = "uvicorn.access"
PYMODBUS_LOGGER = "pymodbus.logging"
"""The logger pymodbus' ``Log`` helper writes to (``logging.getLogger(__name__)`` there)."""


def redact_query(path: str) -> str:
    """``path`` with the values of secret-looking query parameters replaced.

    Parameters
    ----------
    path : str
        A request target as uvicorn logs it, e.g. ``/api/v1/jobs?api_key=abc&since=3``.
    """
    base, sep, query = path.partition("?")
    if not sep:
        return path
    parts = []
    for segment in query.split("&"):
        if "=" not in segment:
            # A bare word (``?s3cr3t``) is not a name=value pair: it may be the key itself.
            if segment:
                parts.append(REDACTED)
            continue
        ((name, value),) = parse_qsl(segment, keep_blank_values=True)
        shown = REDACTED if SECRET_PARAM.search(name) else quote(value, safe="")
        parts.append(f"{quote(name, safe='')}={shown}")
    if not parts and query:
        # Only separators ("?&&"): nothing to show, and nothing worth guessing about.
        return f"{base}?{REDACTED}"
    return f"{base}?{'&'.join(parts)}"


class QueryKeyRedactor(logging.Filter):
    """Redacts secret query parameters in uvicorn access-log records (never drops a record)."""

    def filter(self, record: logging.LogRecord) -> bool:
        args = record.args
        # uvicorn's access record: (client_addr, method, full_path, http_version, status_code)
        if isinstance(args, tuple) and len(args) >= 3 and isinstance(args[2], str):
            record.args = (*args[:2], redact_query(args[2]), *args[3:])
        elif isinstance(record.msg, str) and "?" in record.msg and not args:
            record.msg = " ".join(redact_query(w) for w in record.msg.split(" "))
        return True


class RoutineRequestFilter(logging.Filter):
    """Drops successful reads (GET/HEAD answered below 400) from uvicorn's access log.

    The lab page polls its job once a second and the rig every few seconds: logged, they bury
    what happened (306 lines in six minutes of one scan). Changes (POST, DELETE ...) and every
    refused or failed request stay; ``log_level = "debug"`` keeps the reads too.
    """

    def filter(self, record: logging.LogRecord) -> bool:
        args = record.args
        if isinstance(args, tuple) and len(args) >= 5:
            method, status = args[1], args[4]
            if method in ("GET", "HEAD") and isinstance(status, int) and status < 400:
                return False
        return True


#: What pymodbus logs, at the level of the line before, instead of a line said again.
PYMODBUS_REPEAT = "Repeating...."


class PymodbusFrameFilter(logging.Filter):
    """ERROR records of pymodbus become one-line WARNINGs without the raw frame dump; its
    "Repeating...." records (which say only that the line before happened again) are
    dropped, and so is a line the same as the last one passed within :data:`REPEAT_WINDOW_S`
    (a silent sensor printed "No response received after 0 retries ..." at every poll, 13
    times in one outage: the driver's own fault line says it once)."""

    #: A line the same as the last one passed is dropped for this long, s.
    REPEAT_WINDOW_S = 60.0

    def __init__(self) -> None:
        super().__init__()
        self._last: tuple[str, float] | None = None

    def filter(self, record: logging.LogRecord) -> bool:
        if record.getMessage().strip() == PYMODBUS_REPEAT:
            return False
        if record.levelno >= logging.WARNING and not self._first_in_window(record):
            return False
        if record.levelno >= logging.ERROR:
            text = record.getMessage().split("\n>>>>>", 1)[0].strip()
            # A server-side failure comes with its whole traceback in the message (pymodbus'
            # "Datastore unable to fulfill request: 0; Traceback ..." when a client asks the
            # simulator for a device id it does not have): its last line says what it was.
            head, cut, trace = text.partition("; Traceback (most recent call last):")
            if cut:
                lines = trace.strip().splitlines()
                text = f"{head} ({lines[-1].strip()})" if lines else head
            record.msg = f"{text} (pymodbus; the driver reports the fault)"
            record.args = None
            record.levelno = logging.WARNING
            record.levelname = logging.getLevelName(logging.WARNING)
        return True

    def _first_in_window(self, record: logging.LogRecord) -> bool:
        """False when ``record`` says what the last record passed said, within the window."""
        text = record.getMessage().split("\n>>>>>", 1)[0].strip()
        last = self._last
        if last is not None and last[0] == text and record.created - last[1] < \
                self.REPEAT_WINDOW_S:
            return False
        self._last = (text, record.created)
        return True


def install_pymodbus() -> None:
    """For the ``gonio`` command line (``gonio scan`` and the other commands that talk to a
    rig), idempotent: pymodbus' warnings are not shown and its errors pass through
    :class:`PymodbusFrameFilter`.

    Without a logging configuration a command's warnings reach the terminal through Python's
    last-resort handler, bare: pymodbus' "Failed to connect [Errno 111] ..." and then
    "Repeating...." at every retry, beside the driver's own fault, which names the device, its
    address and what to check. The daemon keeps them in its log (:func:`install`), where
    each line names its logger.
    """
    logging.getLogger("pymodbus").setLevel(logging.ERROR)
    logger = logging.getLogger(PYMODBUS_LOGGER)
    if not any(isinstance(f, PymodbusFrameFilter) for f in logger.filters):
        logger.addFilter(PymodbusFrameFilter())


def install(quiet_reads: bool = True) -> None:
    """Attach the filters to their loggers (idempotent); ``quiet_reads``: also
    :class:`RoutineRequestFilter` (off at debug level)."""
    pairs: list[tuple[str, type[logging.Filter]]] = [
        (ACCESS_LOGGER, QueryKeyRedactor), (PYMODBUS_LOGGER, PymodbusFrameFilter)]
    if quiet_reads:
        pairs.append((ACCESS_LOGGER, RoutineRequestFilter))
    for name, cls in pairs:
        logger = logging.getLogger(name)
        if not any(isinstance(f, cls) for f in logger.filters):
            logger.addFilter(cls())
