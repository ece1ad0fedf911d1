"""How a design request fails: it cannot be computed as asked (:class:`DesignError`), or the rig
cannot physically do it (:class:`FeasibilityError`)."""

from __future__ import annotations

from gonio.brdf.advice import AdvisedError


class DesignError(ValueError):
    """A sampling design that cannot be computed as asked (bad n, too few candidates ...)."""


class DesignTimeout(DesignError):
    """A design that did not finish within its time limit (``time_limit_s``)."""


class FeasibilityError(AdvisedError):
    """Constraints that rule out the design asked for; the advice says what to relax.

    Knobs in the advice are :class:`~gonio.brdf.design.constraints.RigConstraints` fields
    (``max_elevation_deg``, ``min_separation_deg``, ``min_device_distance_deg``); the CLI words
    them as its flags.
    """
