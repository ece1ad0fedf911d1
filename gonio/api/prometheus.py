"""Prometheus text exposition (format 0.0.4), written out by hand.

gonio exports a dozen series. The ``prometheus-client`` package would bring a process-global
default registry, which collides when several apps live in one process (the test suite starts
many); the text format is small and stable, so writing it here costs less than working around that.
Format reference: https://prometheus.io/docs/instrumenting/exposition_formats/
"""

from __future__ import annotations

import math
import threading
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass

CONTENT_TYPE = "text/plain; version=0.0.4; charset=utf-8"

Labels = tuple[tuple[str, str], ...]


def _escape(value: str) -> str:
    return value.replace("\\", "\\\\").replace("\n", "\\n").replace('"', '\\"')


def _labels(labels: Labels, extra: Labels = ()) -> str:
    items = labels + extra
    if not items:
        return ""
    return "{" + ",".join(f'{k}="{_escape(v)}"' for k, v in items) + "}"


def _number(x: float) -> str:
    if math.isnan(x):
        return "NaN"
    if math.isinf(x):
        return "+Inf" if x > 0 else "-Inf"
    return repr(float(x)) if not float(x).is_integer() else str(int(x))


@dataclass(frozen=True)
class Sample:
    """One gauge value at scrape time."""

    name: str
    help: str
    value: float
    labels: Mapping[str, str] | None = None


class RequestStats:
    """Counts HTTP requests and their latency per route template, thread-safe.

    Parameters
    ----------
    buckets : sequence of float
        Upper bounds of the latency histogram, seconds.
    """

    def __init__(self, buckets: Sequence[float] = (0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 1.0)):
        self.buckets = tuple(sorted(buckets))
        self._lock = threading.Lock()
        self._count: dict[Labels, int] = {}
        self._hist: dict[Labels, list[int]] = {}
        self._sum: dict[Labels, float] = {}

    def observe(self, method: str, route: str, status: int, seconds: float) -> None:
        key: Labels = (("method", method), ("route", route), ("status", str(status)))
        hkey: Labels = (("route", route),)
        with self._lock:
            self._count[key] = self._count.get(key, 0) + 1
            counts = self._hist.setdefault(hkey, [0] * (len(self.buckets) + 1))
            for i, b in enumerate(self.buckets):
                if seconds <= b:
                    counts[i] += 1
            counts[-1] += 1  # +Inf
            self._sum[hkey] = self._sum.get(hkey, 0.0) + seconds

    def render(self) -> list[str]:
        out = [
            "# HELP gonio_http_requests_total HTTP requests answered, by route template and "
            "status.",
            "# TYPE gonio_http_requests_total counter",
        ]
        with self._lock:
            for key, n in sorted(self._count.items()):
                out.append(f"gonio_http_requests_total{_labels(key)} {n}")
            out += [
                "# HELP gonio_http_request_duration_seconds Time to answer an HTTP request "
                "(to the first byte for streams).",
                "# TYPE gonio_http_request_duration_seconds histogram",
            ]
            for hkey, counts in sorted(self._hist.items()):
                for b, c in zip((*self.buckets, math.inf), counts, strict=True):
                    le = (("le", _number(b)),)
                    out.append(f"gonio_http_request_duration_seconds_bucket{_labels(hkey, le)} {c}")
                out.append(
                    f"gonio_http_request_duration_seconds_sum{_labels(hkey)} "
                    f"{_number(self._sum[hkey])}"
                )
                out.append(f"gonio_http_request_duration_seconds_count{_labels(hkey)} {counts[-1]}")
        return out


def render(samples: Iterable[Sample], stats: RequestStats | None = None) -> str:
    """The exposition text of ``samples`` (gauges) and the request statistics.

    Samples sharing a name are grouped under one HELP/TYPE header, as the format requires.
    """
    groups: dict[str, list[Sample]] = {}
    for s in samples:
        groups.setdefault(s.name, []).append(s)
    out: list[str] = []
    for name, group in groups.items():
        out.append(f"# HELP {name} {_escape(group[0].help)}")
        out.append(f"# TYPE {name} gauge")
        for s in group:
            labels: Labels = tuple(sorted((s.labels or {}).items()))
            out.append(f"{name}{_labels(labels)} {_number(s.value)}")
    if stats is not None:
        out += stats.render()
    return "\n".join(out) + "\n"
