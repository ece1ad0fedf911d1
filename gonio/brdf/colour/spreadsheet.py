"""CSV text as spreadsheets save it, for the colour files people edit by hand (chart files,
stored standards; docs/colour.md).

A spreadsheet in a locale whose decimal mark is a comma (most of Europe) saves "CSV" with
semicolons between the cells and commas in the numbers (``0,123``); some save tabs. A byte
order mark at the start (UTF-8 "CSV UTF-8") is the caller's to drop (``encoding="utf-8-sig"``).
:func:`csv_rows` reads all of these into the same cells as the comma-separated file gonio
writes.
"""

from __future__ import annotations

import csv
import io
import re

#: A number written with a decimal comma: ``0,123``, ``-1,5``, ``,5``, ``1,2e-3``.
_DECIMAL_COMMA = re.compile(r"^[+-]?\d*,\d+(?:[eE][+-]?\d+)?$")
_DELIMITERS = (",", ";", "\t")


def delimiter_of(header: str) -> str:
    """The cell separator of a CSV file from its header line: the one of comma, semicolon and
    tab it holds most of (comma when it holds none)."""
    counts = {d: header.count(d) for d in _DELIMITERS}
    best = max(_DELIMITERS, key=lambda d: counts[d])
    return best if counts[best] else ","


def csv_rows(text: str) -> list[list[str]]:
    """The rows of CSV ``text``, every cell stripped of surrounding spaces, blank rows left out.

    Cells are separated by commas, semicolons or tabs (:func:`delimiter_of` on the first
    non-blank line). In a file separated by semicolons or tabs a number with a decimal comma
    (``0,123``) is read as ``0.123``; in a comma-separated file a comma can only separate.
    """
    lines = text.splitlines()
    header = next((ln for ln in lines if ln.strip()), "")
    delim = delimiter_of(header)
    out = []
    for row in csv.reader(io.StringIO(text), delimiter=delim):
        cells = [c.strip() for c in row]
        if not any(cells):
            continue
        if delim != ",":
            cells = [c.replace(",", ".") if _DECIMAL_COMMA.match(c) else c for c in cells]
        out.append(cells)
    return out
