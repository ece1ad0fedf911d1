"""Sampling design as the service offers it: request and result models, the computation.

A design request asks for ``pairs`` independent light/sensor pairs, or a product rig of
``lights`` x ``sensors``, under the rig's mounting constraints. The computation is the same as
``gonio design`` (:mod:`gonio.brdf.design`, V&F 2016 Sec. 3.3): minimise the condition
number of the basis rows the pairs sample. The result carries the cells, the lab placement of every
device, the condition number, the roughness bound of MATH 10 at ``rotations`` uniform stage
angles, and the rig-config fragment (TOML) to paste into a rig config.

:func:`run_design` and :func:`evaluate_preset` block for up to the request's time limit;
:meth:`gonio.service.GonioService.design` runs one design at a time against the daemon's
basis, and the API routes call it in a worker thread.
"""

from __future__ import annotations

import math

import numpy as np
from pydantic import BaseModel, Field, model_validator

from gonio.brdf.design.constraints import RigConstraints, parse_exclusion
from gonio.brdf.design.pairs import BasisLike, PairDesign, design_pairs, geometry_design
from gonio.brdf.design.presets import Preset
from gonio.brdf.design.product import design_product_rig
from gonio.brdf.design.roughness import roughness_bound
from gonio.fields import FINITE, Count, Text

MAX_PAIRS = 40
"""More independent pairs than any rig mounts (V&F use up to 20)."""
MAX_DEVICES = 8
"""Per kind in a product rig: 8 x 8 = 64 induced pairs."""
MAX_TIME_LIMIT_S = 600.0
"""Schema bound of ``time_limit_s``; the daemon's own limit is usually lower (``[limits]``)."""
DEFAULT_TIME_LIMIT_S = 10.0


class DesignRequest(BaseModel):
    """What to optimise, under which mounting limits, for how long."""

    model_config = FINITE

    pairs: Count | None = Field(None, ge=1, le=MAX_PAIRS,
                              description="number of independent light/sensor pairs")
    lights: Count | None = Field(None, ge=1, le=MAX_DEVICES,
                               description="product rig: lights, each measured with every sensor")
    sensors: Count | None = Field(None, ge=1, le=MAX_DEVICES, description="product rig: sensors")
    max_elevation_deg: float = Field(80.0, gt=0, lt=90,
                                     description="largest device angle from the normal, degrees")
    min_separation_deg: float = Field(10.0, ge=0, lt=180,
                                      description="smallest light-sensor angle of a pair, degrees")
    min_device_distance_deg: float = Field(
        10.0, ge=0, lt=180, description="smallest angle between any two devices, degrees")
    exclusions: list[Text] = Field(
        default_factory=list, max_length=32,
        description="lab regions without devices: 'cone:THETA,PHI,RADIUS' or "
                    "'box:THETA_MIN,THETA_MAX,PHI_MIN,PHI_MAX' (degrees)")
    seed: Count = Field(0, ge=0, le=2**31 - 1, description="random seed of the search")
    time_limit_s: float | None = Field(
        None, gt=0, le=MAX_TIME_LIMIT_S,
        description="stop starting new descents after this long, seconds; at most the daemon's "
                    f"design time limit (default: {DEFAULT_TIME_LIMIT_S:g} s or that limit, if "
                    "lower)")
    starts: Count = Field(10, ge=1, le=100, description="random starts")
    descents: Count = Field(10, ge=1, le=100, description="descents per start (pairs only)")
    neighbourhood: Count = Field(7, ge=1, le=15, description="odd neighbourhood size of the search")
    rotations: Count = Field(8, ge=1, le=360,
                           description="uniform stage angles for the roughness bound")

    @model_validator(mode="after")
    def _one_kind(self) -> DesignRequest:
        product = self.lights is not None or self.sensors is not None
        if self.pairs is not None and product:
            raise ValueError("give either 'pairs' or 'lights' and 'sensors', not both")
        if self.pairs is None and not product:
            raise ValueError("say what to design: 'pairs' (independent pairs) or 'lights' and "
                             "'sensors' (a product rig)")
        if product and (self.lights is None or self.sensors is None):
            raise ValueError("a product rig needs both 'lights' and 'sensors'")
        if self.neighbourhood % 2 == 0:
            raise ValueError(f"'neighbourhood' must be odd, got {self.neighbourhood}")
        return self

    def constraints(self) -> RigConstraints:
        """The mounting limits (raises ``FeasibilityError`` for an unreadable exclusion)."""
        return RigConstraints(
            max_elevation_deg=self.max_elevation_deg,
            min_separation_deg=self.min_separation_deg,
            min_device_distance_deg=self.min_device_distance_deg,
            exclusions=tuple(parse_exclusion(e) for e in self.exclusions),
        )


class Device(BaseModel):
    name: str = Field(description="L1, L2, ... for lights; S1, S2, ... for sensors")
    theta_deg: float = Field(description="angle from the specimen normal, degrees")
    phi_deg: float = Field(description="lab azimuth, degrees in [0, 360)")


class DesignPair(BaseModel):
    """One measured pair: its half/difference cell and its devices."""

    light: str
    sensor: str
    theta_h_deg: float
    theta_d_deg: float
    phi_d_deg: float
    phi_h_lab_deg: float = Field(description="lab half-vector azimuth at stage angle 0, degrees")


class RoughnessInfo(BaseModel):
    """MATH 10: the smallest microfacet roughness the design resolves at ``rotations`` angles."""

    rotations: int
    alpha_min: float | None = Field(description="alpha'; null when nothing is resolvable")
    n_effective: float = Field(description="effective samples near the specular direction")
    degree: int = Field(description="resolvable spherical-harmonic degree l*")
    cap_deg: float


class SearchInfo(BaseModel):
    neighbourhoods: int
    evaluations: int
    seconds: float


class DesignResult(BaseModel):
    """A geometry, how well it conditions the reconstruction, and how to mount it."""

    name: str = Field(description="'optimized', 'product' or the preset's name")
    n_pairs: int
    condition_number: float | None = Field(
        description="of the pairs' basis rows (lower is better); null if singular")
    min_device_distance_deg: float = Field(description="closest two devices, degrees")
    lights: list[Device]
    sensors: list[Device]
    pairs: list[DesignPair]
    roughness: RoughnessInfo
    search: SearchInfo | None = Field(None, description="search statistics (optimized pairs)")
    rig_config_toml: str = Field(
        description="[[lights]], [[sensors]] and pairs, to merge into a rig config (each device "
                    "still needs its driver settings)")


class PresetInfo(BaseModel):
    name: str
    description: str
    n_pairs: int


def _finite(x: float) -> float | None:
    return float(x) if math.isfinite(x) else None


def describe(design: PairDesign, rotations: int) -> DesignResult:
    """The API view of a :class:`~gonio.brdf.design.pairs.PairDesign`."""
    from gonio.rigdesign import design_fragment, dump_fragment

    angles = np.arange(rotations) * (2.0 * np.pi / rotations)
    bound = roughness_bound(design.cells, design.ph_lab, angles)
    frag = design_fragment(design)
    lights = [Device(**d) for d in frag["lights"]]
    sensors = [Device(**d) for d in frag["sensors"]]
    cells = np.rad2deg(design.cells)
    ph = np.rad2deg(design.ph_lab) % 360.0
    pairs = [
        DesignPair(light=lights[a].name, sensor=sensors[b].name, theta_h_deg=float(c[0]),
                   theta_d_deg=float(c[1]), phi_d_deg=float(c[2]), phi_h_lab_deg=float(p))
        for (a, b), c, p in zip(design.pairs.tolist(), cells, ph, strict=True)
    ]
    search = design.search
    return DesignResult(
        name=design.name,
        n_pairs=design.n_pairs,
        condition_number=_finite(design.kappa),
        min_device_distance_deg=float(design.min_distance_deg),
        lights=lights,
        sensors=sensors,
        pairs=pairs,
        roughness=RoughnessInfo(rotations=rotations, alpha_min=_finite(bound.alpha_min),
                                n_effective=float(bound.n_effective), degree=int(bound.degree),
                                cap_deg=float(bound.cap_deg)),
        search=None if search is None else SearchInfo(
            neighbourhoods=search.neighbourhoods, evaluations=search.evaluations,
            seconds=search.seconds),
        rig_config_toml=dump_fragment(frag),
    )


def run_design(basis: BasisLike, request: DesignRequest) -> DesignResult:
    """Optimise the geometry ``request`` asks for (blocking, up to about its time limit).

    Raises
    ------
    gonio.brdf.design.errors.FeasibilityError, gonio.brdf.design.errors.DesignError
        Constraints that no design satisfies; the message says which to relax.
    """
    constraints = request.constraints()
    if request.pairs is not None:
        design = design_pairs(
            basis, request.pairs, constraints, h=request.neighbourhood, starts=request.starts,
            descents=request.descents, seed=request.seed, time_limit_s=request.time_limit_s,
        )
    else:
        assert request.lights is not None and request.sensors is not None
        design = design_product_rig(
            basis, request.lights, request.sensors, constraints, h=request.neighbourhood,
            starts=request.starts, seed=request.seed, time_limit_s=request.time_limit_s,
        )
    return describe(design, request.rotations)


def evaluate_preset(basis: BasisLike, preset: Preset, rotations: int) -> DesignResult:
    """An industrial geometry evaluated like an optimised one (V&F Table 1)."""
    wi, wo = preset.directions()
    n = preset.n_pairs
    design = geometry_design(basis, preset.name, wi, wo, np.stack([np.arange(n)] * 2, axis=1))
    return describe(design, rotations)
