"""Sparse rotation-stage samples: simulation with a noise model, and the samples file.

A scan reads ``n`` fixed light/sensor pairs at ``r`` stage angles. Each pair is one cell
``(th, td, pd)`` of the isotropic slice plus its lab half-vector azimuth ``ph_lab``; at stage
angle ``alpha`` it sees the specimen at ``(th, ph_lab - alpha, td, pd)`` (math.md 2).

Samples file (``.npz``, readable with ``numpy.load`` alone)
-----------------------------------------------------------
=================  ====================  =====================================================
key                shape / dtype         meaning
=================  ====================  =====================================================
``format``         () str                ``"gonio-samples"``
``version``        () int                format version, currently 1
``cells``          (n, 3) float64        ``(th, td, pd)`` of each pair, radians
``ph_lab``         (n,) float64          lab half-vector azimuth of each pair, radians
``stage_angles``   (r,) float64          stage angles, radians
``values``         (n, r, C) float64     BRDF values, 1/sr (cosine not included)
``channels``       (C,) str              channel names
``provenance``     () str                JSON object: where the samples came from
=================  ====================  =====================================================
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from gonio.brdf.tables import geometry as geo
from gonio.brdf.tables.npzfile import read_npz, write_npz

FloatArray = NDArray[np.float64]
FORMAT_NAME = "gonio-samples"
FORMAT_VERSION = 1


class SamplesError(ValueError):
    """Samples or a samples file are malformed; the message says what and what to do."""


class Evaluable(Protocol):
    """Anything with ``eval(wi, wo) -> (N, C)`` in the specimen frame (models, tables)."""

    def eval(self, wi: ArrayLike, wo: ArrayLike) -> Any: ...


@dataclass(frozen=True)
class NoiseModel:
    """Sensor noise: ``v' = v (1 + relative N1) + absolute N2``, clamped at 0.

    Parameters
    ----------
    relative : float
        Standard deviation of the multiplicative (shot/gain) noise, a fraction of the value.
    absolute : float, 1/sr
        Standard deviation of the additive (read/dark) noise.
    seed : int
        Seed of the generator; the same seed gives the same noise.
    """

    relative: float = 0.01
    absolute: float = 0.0
    seed: int = 0

    def __post_init__(self) -> None:
        if not (self.relative >= 0 and self.absolute >= 0):
            raise SamplesError(
                f"noise levels must be >= 0, got relative={self.relative}, "
                f"absolute={self.absolute}"
            )

    def apply(self, values: FloatArray) -> FloatArray:
        """Noisy copy of ``values`` (any shape), clamped at 0."""
        if self.relative == 0 and self.absolute == 0:
            return values.copy()
        rng = np.random.default_rng(self.seed)
        noisy = values * (1.0 + self.relative * rng.standard_normal(values.shape))
        noisy = noisy + self.absolute * rng.standard_normal(values.shape)
        return np.asarray(np.maximum(noisy, 0.0))


def pair_directions(cells: ArrayLike, ph_lab: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """Lab light and sensor unit vectors (n, 3) of pairs at stage angle 0."""
    c = np.asarray(cells, dtype=float)
    return geo.half_diff_to_directions(c[:, 0], np.asarray(ph_lab, dtype=float), c[:, 1], c[:, 2])


def simulate_samples(
    brdf: Evaluable,
    cells: ArrayLike,
    ph_lab: ArrayLike,
    stage_angles: ArrayLike,
    *,
    noise: NoiseModel | None = None,
) -> FloatArray:
    """What a rig with fixed pairs would read from ``brdf`` while the stage turns.

    Parameters
    ----------
    brdf : object with ``eval(wi, wo) -> (N, C)``
        The specimen (an analytic model or a :class:`BRDFTable`), specimen frame, 1/sr.
    cells : (n, 3) array_like, radians
        ``(th, td, pd)`` of each pair.
    ph_lab : (n,) array_like, radians
        Lab half-vector azimuth of each pair.
    stage_angles : (r,) array_like, radians
    noise : NoiseModel, optional
        Defaults to ``NoiseModel(relative=0.01, absolute=0.0, seed=0)``; pass
        ``NoiseModel(0, 0)`` for exact values.

    Returns
    -------
    (n, r, C) float64, 1/sr
    """
    noise = NoiseModel() if noise is None else noise
    c = np.asarray(cells, dtype=float)
    ph = np.asarray(ph_lab, dtype=float)
    alpha = np.asarray(stage_angles, dtype=float)
    if c.ndim != 2 or c.shape[1] != 3 or c.shape[0] == 0:
        raise SamplesError(f"cells must be a non-empty (n, 3) array, got shape {c.shape}")
    if ph.shape != (c.shape[0],):
        raise SamplesError(f"ph_lab has shape {ph.shape}; expected ({c.shape[0]},)")
    if alpha.ndim != 1 or alpha.size == 0:
        raise SamplesError(f"stage_angles must be a non-empty 1-D array, got shape {alpha.shape}")
    wi_lab, wo_lab = pair_directions(c, ph)
    if (wi_lab[:, 2] <= 0).any() or (wo_lab[:, 2] <= 0).any():
        raise SamplesError("some pairs put the light or the sensor below the horizon")
    # (n, r, 3): the lab directions seen from the specimen at every stage angle.
    wi = geo.lab_to_specimen(wi_lab[:, None, :], alpha[None, :])
    wo = geo.lab_to_specimen(wo_lab[:, None, :], alpha[None, :])
    n, r = c.shape[0], alpha.size
    vals = np.asarray(brdf.eval(wi.reshape(-1, 3), wo.reshape(-1, 3)), dtype=float)
    vals = vals.reshape(n, r, -1)
    if not np.isfinite(vals).all():
        raise SamplesError("the BRDF returned NaN or infinite values at some pairs")
    return noise.apply(np.maximum(vals, 0.0))


# ---------------------------------------------------------------------------- file
@dataclass(frozen=True)
class Samples:
    """The contents of a samples file (see the module docstring for units and shapes)."""

    cells: FloatArray
    ph_lab: FloatArray
    stage_angles: FloatArray
    values: FloatArray
    channels: tuple[str, ...]
    provenance: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        cells = np.asarray(self.cells, dtype=float)
        ph = np.asarray(self.ph_lab, dtype=float)
        alpha = np.asarray(self.stage_angles, dtype=float)
        vals = np.asarray(self.values, dtype=float)
        channels = tuple(str(x) for x in self.channels)
        if cells.ndim != 2 or cells.shape[1] != 3 or cells.shape[0] == 0:
            raise SamplesError(f"cells must be a non-empty (n, 3) array, got {cells.shape}")
        n = cells.shape[0]
        if ph.shape != (n,):
            raise SamplesError(f"ph_lab has shape {ph.shape}; expected ({n},)")
        if alpha.ndim != 1 or alpha.size == 0:
            raise SamplesError(f"stage_angles must be non-empty and 1-D, got {alpha.shape}")
        if vals.shape != (n, alpha.size, len(channels)):
            raise SamplesError(
                f"values have shape {vals.shape}; expected (pairs, rotations, channels) = "
                f"({n}, {alpha.size}, {len(channels)})"
            )
        object.__setattr__(self, "cells", cells)
        object.__setattr__(self, "ph_lab", ph)
        object.__setattr__(self, "stage_angles", alpha)
        object.__setattr__(self, "values", vals)
        object.__setattr__(self, "channels", channels)
        object.__setattr__(self, "provenance", dict(self.provenance))

    def save(self, path: str | os.PathLike[str]) -> Path:
        """Write the samples file (``.npz``); returns the path."""
        return write_npz(
            path, FORMAT_NAME, FORMAT_VERSION, self.provenance,
            cells=self.cells, ph_lab=self.ph_lab, stage_angles=self.stage_angles,
            values=self.values, channels=np.array(self.channels, dtype=str),
        )

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> Samples:
        """Read a samples file; :class:`SamplesError` saying what is wrong otherwise."""
        data, prov = read_npz(
            path, format_name=FORMAT_NAME, version=FORMAT_VERSION,
            required=("cells", "ph_lab", "stage_angles", "values", "channels"),
            error=SamplesError, kind="samples",
            how_to_make=(
                "create one with `gonio simulate-scan` or "
                "gonio.brdf.reconstruction.samples.Samples.save"
            ),
        )
        try:
            return cls(
                data["cells"], data["ph_lab"], data["stage_angles"], data["values"],
                tuple(np.asarray(data["channels"]).tolist()), prov,
            )
        except SamplesError as exc:
            raise SamplesError(f"{Path(path)}: {exc}") from None

#: Arc (degrees) the stage angles of a uniform scan cover by default: half a turn. The joint
#: fit's learnt prior along ``ph`` holds only even harmonics (reciprocity and the twofold
#: symmetry of brushed, woven and microfacet lobes, docs/science.md 2.1), so a specimen turned
#: by half a turn gives the same readings: ``r`` angles over half a turn show each pair ``r``
#: distinct azimuths, over a full turn only ``r / 2`` (each seen twice). A full turn is for
#: specimens without that symmetry (a pile's lean, blazed or sawtooth structures).
DEFAULT_SPAN_DEG = 180.0
#: Half a turn, degrees: the arc that relies on the twofold symmetry.
HALF_TURN_DEG = 180.0
#: The arcs a uniform scan may cover (degrees): half a turn or a full turn.
SPANS_DEG = (HALF_TURN_DEG, 360.0)


def span_periods(span_deg: float) -> int:
    """How many times ``span_deg`` fits in a full turn: 2 for half a turn, 1 for a full turn.

    Raises
    ------
    SamplesError
        For any other arc: uniform angles over, say, 90 degrees would leave the azimuths of the
        other quarter turns unseen, which no shipped prior can fill in.
    """
    if span_deg not in SPANS_DEG:
        raise SamplesError(
            f"the stage angles cover half a turn or a full turn: span must be 180 or 360 "
            f"degrees, got {span_deg:g}")
    return round(360.0 / span_deg)


def uniform_stage_angles(r: int, start: float = 0.0, span: float = 2 * np.pi) -> FloatArray:
    """``r`` evenly spaced stage angles (radians) ``start + k span / r``.

    Parameters
    ----------
    r : int, >= 1
    start : float, radians
    span : float, radians
        The arc the angles cover (a full turn by default; scans use
        :data:`DEFAULT_SPAN_DEG`).

    Returns
    -------
    (r,) radians
    """
    if r < 1:
        raise SamplesError(f"need at least one rotation, got {r}")
    return np.asarray(start + span * np.arange(r) / r)


def channels_of(names: Sequence[str] | None, n: int) -> tuple[str, ...]:
    """Channel names for ``n`` channels: the given ones or RGB for three."""
    if names is not None:
        return tuple(names)
    return ("R", "G", "B") if n == 3 else tuple(f"c{i}" for i in range(n))
