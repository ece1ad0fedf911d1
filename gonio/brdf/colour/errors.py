"""The colour room's error, apart from the maths so that catching it imports no colour library."""

from __future__ import annotations


class ColourError(ValueError):
    """A colour computation cannot be done as asked; the message says why and what to do."""
