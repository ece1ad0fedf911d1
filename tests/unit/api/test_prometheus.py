"""The metrics page in Prometheus' text format 0.0.4 (prometheus.io, "Exposition formats"):
HELP and TYPE once per metric, escaped label values, histogram buckets cumulative with +Inf."""

from __future__ import annotations

import math

from gonio.api.prometheus import CONTENT_TYPE, RequestStats, Sample, render


def test_gauges_are_grouped_under_one_header() -> None:
    text = render([
        Sample("gonio_jobs", "Jobs by state.", 2, {"state": "queued"}),
        Sample("gonio_up", "1 when up.", 1.0),
        Sample("gonio_jobs", "Jobs by state.", 0.5, {"state": "running"}),
    ])
    assert text == (
        "# HELP gonio_jobs Jobs by state.\n"
        "# TYPE gonio_jobs gauge\n"
        'gonio_jobs{state="queued"} 2\n'
        'gonio_jobs{state="running"} 0.5\n'
        "# HELP gonio_up 1 when up.\n"
        "# TYPE gonio_up gauge\n"
        "gonio_up 1\n"
    )
    assert CONTENT_TYPE == "text/plain; version=0.0.4; charset=utf-8"


def test_label_values_and_help_are_escaped_and_special_numbers_spelled() -> None:
    text = render([
        Sample("m", 'a "help"\nline \\', math.nan, {"b": 'x"y', "a": "1\\2\n3"}),
        Sample("m", "", math.inf), Sample("m", "", -math.inf),
    ])
    lines = text.splitlines()
    assert lines[0] == '# HELP m a \\"help\\"\\nline \\\\'
    # labels sorted by name; backslash, double quote and newline escaped
    assert lines[2] == 'm{a="1\\\\2\\n3",b="x\\"y"} NaN'
    assert lines[3:] == ["m +Inf", "m -Inf"]


def test_request_histogram_is_cumulative_with_sum_and_count() -> None:
    stats = RequestStats(buckets=(0.1, 0.01))  # given unsorted: sorted
    stats.observe("GET", "/api/v1/jobs", 200, 0.005)
    stats.observe("GET", "/api/v1/jobs", 200, 0.05)
    stats.observe("POST", "/api/v1/jobs", 422, 2.0)
    lines = render([], stats).splitlines()
    assert 'gonio_http_requests_total{method="GET",route="/api/v1/jobs",status="200"} 2' in lines
    assert 'gonio_http_requests_total{method="POST",route="/api/v1/jobs",status="422"} 1' in lines
    bucket = 'gonio_http_request_duration_seconds_bucket{route="/api/v1/jobs",le="%s"} %d'
    assert [bucket % ("0.01", 1), bucket % ("0.1", 2), bucket % ("+Inf", 3)] == [
        ln for ln in lines if "_bucket" in ln]
    assert 'gonio_http_request_duration_seconds_sum{route="/api/v1/jobs"} 2.055' in lines
    assert 'gonio_http_request_duration_seconds_count{route="/api/v1/jobs"} 3' in lines
    assert "# TYPE gonio_http_request_duration_seconds histogram" in lines
    assert "# TYPE gonio_http_requests_total counter" in lines


def test_no_requests_yet_gives_the_headers_only() -> None:
    lines = render([], RequestStats()).splitlines()
    assert [ln for ln in lines if not ln.startswith("#")] == []
