"""CSV text as spreadsheets save it (gonio.brdf.colour.spreadsheet)."""

from __future__ import annotations

import pytest

from gonio.brdf.colour.spreadsheet import csv_rows, delimiter_of

ROWS = [["patch", "R", "400"], ["dark skin", "0.12", "-1.5e-3"], ["white", "0.9", "0.88"]]


@pytest.mark.parametrize("text", [
    "patch,R,400\ndark skin,0.12,-1.5e-3\nwhite,0.9,0.88\n",
    "patch;R;400\r\ndark skin;0,12;-1,5e-3\r\n;;\r\n\r\nwhite;0,9;0,88\r\n",
    "patch\tR\t400\ndark skin\t0,12\t-1.5e-3\nwhite\t0.9\t0,88\n",
    " patch , R , 400 \n\"dark skin\" , 0.12 ,-1.5e-3\n,,\nwhite,0.9,0.88\n",
])
def test_every_spreadsheet_form_gives_the_same_cells(text: str) -> None:
    assert csv_rows(text) == ROWS


def test_a_comma_file_keeps_its_commas_as_separators() -> None:
    # A quoted name with a comma stays one cell; "0,5" in a comma file is not a number.
    assert csv_rows('patch,R\n"red, dark",0.5\n') == [["patch", "R"], ["red, dark", "0.5"]]
    assert csv_rows("patch;name\np;red, dark\n") == [["patch", "name"], ["p", "red, dark"]]


def test_the_delimiter_is_the_header_line_s_commonest() -> None:
    assert delimiter_of("a;b;c") == ";" and delimiter_of("a\tb") == "\t"
    assert delimiter_of("a,b;c,d") == "," and delimiter_of("patch") == ","
    assert csv_rows("") == []
