"""The error every reconstruction step raises for unusable input."""

from __future__ import annotations


class ReconstructionError(ValueError):
    """Reconstruction inputs are unusable; the message says what and what to do."""
