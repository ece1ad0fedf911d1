"""How a design request fails: it cannot be computed as asked (:class:`DesignError`), or the rig
cannot physically do it (:class:`FeasibilityError`)."""

from __future__ import annotations


class DesignError(ValueError):
    """A sampling design that cannot be computed as asked (bad n, too few candidates ...)."""


class FeasibilityError(ValueError):
    """Constraints that rule out the design asked for; the message says what to relax."""
