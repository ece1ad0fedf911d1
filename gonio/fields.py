"""Validated field types shared by the request models (plans, designs, rig settings).

Each type refuses at the door what could not be stored, timed or shown later, so a bad value is
a clear 422 before anything runs rather than a failure after a scan was measured.
"""

from __future__ import annotations

import unicodedata
from typing import Annotated

from pydantic import AfterValidator, ConfigDict, Field


def check_text(value: str) -> str:
    """Refuse text that cannot be stored, written to HDF5 or shown: control characters
    (NUL included) and lone surrogates. Returns ``value`` unchanged.

    Names travel into SQLite, HDF5 attributes (which cannot hold NUL), file names of exports
    and log lines; refusing them at the door means a scan is never measured and then lost.
    """
    for i, ch in enumerate(value):
        cat = unicodedata.category(ch)
        if cat == "Cc":
            raise ValueError(
                f"contains the control character U+{ord(ch):04X} at position {i}; "
                "use printable text only"
            )
        if cat == "Cs":
            raise ValueError(
                f"contains a lone surrogate U+{ord(ch):04X} at position {i} (not valid "
                "Unicode text); send the name as valid UTF-8"
            )
    return value


Text = Annotated[str, AfterValidator(check_text)]
"""A user-supplied name or label: printable Unicode, no control characters."""

Count = Annotated[int, Field(strict=True)]
"""An integer that must be sent as one: JSON ``true`` or ``8.0`` is not a count."""

FINITE = ConfigDict(extra="forbid", allow_inf_nan=False)
"""Config of every request model: unknown keys and NaN / Infinity (JSON 1e999) refused."""
