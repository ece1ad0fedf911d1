"""How a design request fails: it cannot be computed as asked (:class:`DesignError`)."""

from __future__ import annotations


class DesignError(ValueError):
    """A sampling design that cannot be computed as asked (bad n, too few candidates ...)."""
