"""Counts in messages: "1 stage angle", "8 stage angles".

Messages the lab reads (the console, the CLI, API errors) put a count before a noun; written as
``f"{n} stage angles"`` they said "1 stage angles" for a one-angle scan or a one-pair plan.
"""

from __future__ import annotations


def counted(n: int, noun: str, plural: str | None = None) -> str:
    """``n`` and ``noun``, the noun plural unless ``n`` is 1.

    Parameters
    ----------
    n
        The count.
    noun
        The noun in the singular; its last word takes the plural (``"stage angle"``).
    plural
        The plural when it is not ``noun`` + ``"s"``.

    Returns
    -------
    str
        ``"1 stage angle"``, ``"0 stage angles"``, ``"12 pairs"``.
    """
    return f"{n} {noun if n == 1 else plural or noun + 's'}"
