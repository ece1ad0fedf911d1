"""Sampling design as the service offers it: request and result models, the computation.

A design request asks for ``pairs`` independent light/sensor pairs, or a product rig of
``lights`` x ``sensors``, under the rig's mounting constraints. The computation is the same as
``gonio design`` (:mod:`gonio.brdf.design`): independent pairs by the request's ``objective``,
V&F's condition number (2016 Sec. 3.3) or the joint fit's expected error
(``docs/science.md`` 7.2.1), :data:`~gonio.brdf.design.pairs.DEFAULT_OBJECTIVE` when none is
given; product rigs by the condition number. The result carries the cells, the lab placement
of every device, the objective that chose them, the condition number and the joint fit's
expected log_rmse, the roughness bound of math.md 11 at ``rotations`` uniform stage angles, the
statistics of the search that ran, and the rig-config fragment (TOML) to paste into a rig
config.

:func:`run_design` and :func:`evaluate_preset` block for up to the request's time limit;
:meth:`gonio.service.GonioService.design` runs one design at a time against the daemon's
basis, and the API routes call it in a worker thread.
"""

from __future__ import annotations

import math
from typing import Any, Literal

import numpy as np
from pydantic import BaseModel, Field, model_validator

from gonio.brdf.colour.conditions import ColourError
from gonio.brdf.colour.instruments import canonical_instrument, geometries
from gonio.brdf.design.colourtargets import (
    DEFAULT_COLOUR_WEIGHT,
    MAX_COLOUR_WEIGHT,
    ColourTargets,
)
from gonio.brdf.design.constraints import RigConstraints, parse_exclusion
from gonio.brdf.design.pairs import (
    BasisLike,
    PairDesign,
    design_pairs,
    geometry_design,
    with_expected_error,
)
from gonio.brdf.design.presets import Preset
from gonio.brdf.design.product import design_product_rig
from gonio.brdf.design.renderweight import cell_weighting
from gonio.brdf.design.roughness import bound_angles, roughness_bound
from gonio.brdf.mirrorgap import cells_gap_deg, gap_note
from gonio.fields import FINITE, Count, Text
from gonio.plans.models import DEFAULT_SPAN_DEG, SpanDeg

MAX_PAIRS = 40
"""More independent pairs than any rig mounts (V&F use up to 20)."""
MAX_DEVICES = 8
"""Per kind in a product rig: 8 x 8 = 64 induced pairs."""
MAX_TIME_LIMIT_S = 600.0
"""Schema bound of ``time_limit_s``; the daemon's own limit is usually lower (``[limits]``)."""
DEFAULT_TIME_LIMIT_S = 10.0


def colour_targets(instrument: str, weight: float = DEFAULT_COLOUR_WEIGHT) -> ColourTargets:
    """The design's colour targets for ``instrument``: its in-plane geometries with the plane
    of incidence along the specimen's reference mark (:mod:`gonio.brdf.colour.instruments`).

    Raises
    ------
    gonio.brdf.colour.conditions.ColourError
        An unknown instrument (the message lists the known ones).
    gonio.brdf.design.errors.DesignError
        A weight below 0 or not a number.
    """
    g = geometries([instrument])
    return ColourTargets(np.stack([x.directions()[0] for x in g]),
                         np.stack([x.directions()[1] for x in g]), weight=weight)


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
    objective: Literal["kappa", "posterior"] | None = Field(
        None, description="what chooses independent pairs: 'kappa' (V&F's condition-number "
                          "search) or 'posterior' (the joint fit's expected error at "
                          "'rotations' stage angles); default: gonio's default objective "
                          "(gonio.brdf.design.pairs.DEFAULT_OBJECTIVE). Product rigs always "
                          "use the condition number")
    seed: Count = Field(0, ge=0, le=2**31 - 1,
                        description="random seed of the kappa search; for 'posterior' it picks "
                                    "the first pair the greedy choice starts from (0: the best "
                                    "single pair, k: the k-th best, modulo 64)")
    time_limit_s: float | None = Field(
        None, gt=0, le=MAX_TIME_LIMIT_S,
        description="stop starting new descents after this long, seconds; at most the daemon's "
                    f"design time limit (default: {DEFAULT_TIME_LIMIT_S:g} s or that limit, if "
                    "lower)")
    starts: Count = Field(10, ge=1, le=100, description="random starts")
    descents: Count = Field(10, ge=1, le=100, description="descents per start (pairs only)")
    neighbourhood: Count = Field(7, ge=1, le=15, description="odd neighbourhood size of the search")
    rotations: Count = Field(8, ge=1, le=360,
                           description="uniform stage angles of the scan: for the roughness "
                                       "bound, the expected log_rmse and the 'posterior' "
                                       "objective")
    span_deg: SpanDeg = Field(DEFAULT_SPAN_DEG,
                              description="arc those angles cover, degrees: 180 (half a turn, "
                                          "the scans' default) or 360")
    colour_instrument: Text | None = Field(
        None, description="design for colour at this multi-angle instrument's geometries "
                          "(MA68, MA98, BYK-mac, MultiFX10; docs/colour.md 'Designing for "
                          "colour'): a pair at each near-specular one, the others weighted "
                          "toward the rest; pairs with the 'posterior' objective only")
    colour_weight: float = Field(
        DEFAULT_COLOUR_WEIGHT, ge=0, le=MAX_COLOUR_WEIGHT,
        description="with 'colour_instrument': how much the instrument geometries' expected "
                    "error counts against the whole table's (0: only their direct pairs)")
    render_mix: float | None = Field(
        None, ge=0, le=1,
        description="the share of the standard renderings' weighting of the grid's cells in "
                    "the expected-error objective of 'pairs' (docs/science.md 7.2.2); null: the "
                    "design's default (0.5), 0: weigh the cells as log_rmse does alone")

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
        if product and self.objective is not None:
            raise ValueError("'objective' chooses independent pairs; a product rig is always "
                             "designed by the condition number: drop 'objective' or ask for "
                             "'pairs'")
        if self.neighbourhood % 2 == 0:
            raise ValueError(f"'neighbourhood' must be odd, got {self.neighbourhood}")
        if self.colour_instrument is not None:
            if self.pairs is None or self.objective == "kappa":
                raise ValueError("'colour_instrument' designs independent 'pairs' by the "
                                 "expected error: ask for 'pairs' and drop objective 'kappa'")
            try:
                canonical_instrument(self.colour_instrument)
            except ColourError as exc:
                raise ValueError(f"'colour_instrument': {exc}") from None
        if self.render_mix:
            if self.pairs is None or self.objective == "kappa":
                raise ValueError("'render_mix' weighs the expected-error design of 'pairs': "
                                 + ("a product rig takes none (drop render_mix)"
                                    if self.pairs is None else
                                    "drop objective 'kappa' or render_mix"))
            if self.colour_instrument is not None:
                raise ValueError("'render_mix' and 'colour_instrument' both reweigh the "
                                 "expected error and cannot be combined: use one")
        return self

    def cells_weighting(self) -> dict[str, Any]:
        """``design_pairs``' ``cell_weight`` / ``cell_mix`` for ``render_mix``."""
        return cell_weighting(self.render_mix)

    def colour(self) -> ColourTargets | None:
        """The colour targets asked for, or None."""
        if self.colour_instrument is None:
            return None
        return colour_targets(self.colour_instrument, self.colour_weight)


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


# Its docstring is the API schema's description; a design fragment's pair (device names
# only) is gonio.rigdesign.FragmentPair.
class DesignPair(BaseModel):
    """One measured pair: its half/difference cell and its devices."""

    light: str
    sensor: str
    theta_h_deg: float
    theta_d_deg: float
    phi_d_deg: float
    phi_h_lab_deg: float = Field(description="lab half-vector azimuth at stage angle 0, degrees")


class RoughnessInfo(BaseModel):
    """math.md 11: the smallest microfacet roughness the design resolves at ``rotations`` angles."""

    rotations: int
    span_deg: float = Field(description="arc of the angles, degrees; over half a turn the "
                                        "bound counts each angle also half a turn on (the "
                                        "same reading for a twofold-symmetric specimen)")
    alpha_min: float | None = Field(description="alpha'; null when nothing is resolvable")
    n_effective: float = Field(description="effective samples near the specular direction")
    degree: int = Field(description="resolvable spherical-harmonic degree l*")
    cap_deg: float


class SearchInfo(BaseModel):
    """What the condition-number search did."""

    neighbourhoods: int
    evaluations: int
    seconds: float


class GreedyInfo(BaseModel):
    """What the expected-error choice did."""

    candidates: int = Field(description="feasible cells scored at each step")
    evaluations: int = Field(description="candidate scorings over all steps")
    mount_checks: int = Field(description="placements tried to keep every choice mountable")
    first: int = Field(description="rank of the first pair among single-pair gains (the seed "
                                          "modulo 64; 0: the best)")
    seconds: float


class DesignResult(BaseModel):
    """A geometry, how well it conditions the reconstruction, and how to mount it."""

    name: str = Field(description="'optimized', 'product' or the preset's name")
    n_pairs: int
    condition_number: float | None = Field(
        description="of the pairs' basis rows (lower is better); null if singular")
    objective: Literal["kappa", "posterior"] | None = Field(
        None, description="the objective that chose the pairs (null for presets and product "
                          "rigs); differs from the one asked for only with 'fallback'")
    expected_log_rmse: float | None = Field(
        None, description="the joint fit's expected log_rmse at 'roughness.rotations' stage "
                          "angles under the basis' prior: the error the readings leave inside "
                          "the basis (what it cannot represent is not in it; lower is better)")
    fallback: str | None = Field(
        None, description="why the objective asked for did not make the design (e.g. its "
                          "choice could not be mounted); null when it did")
    colour_pairs: int = Field(
        0, description="how many of the pairs (the first ones) sit at the colour instrument's "
                       "near-specular geometries ('colour_instrument'); 0 without colour")
    render_mix: float = Field(
        0.0, description="the share of the standard renderings' weighting of the grid's cells "
                         "in the expected-error objective that chose the pairs (0.5 by default, "
                         "docs/science.md 7.2.2); 0 for an unweighted design, a preset, a "
                         "product rig, a colour design or a condition-number design (asked "
                         "for, or the fallback)")
    min_device_distance_deg: float = Field(description="closest two devices, degrees")
    mirror_gap_deg: float = Field(
        description="the least tilt of a pair's half vector from the specimen normal (the "
                    "least theta_h_deg), degrees: no stage angle reads nearer the mirror "
                    "direction (docs/design.md, the mirror gap)")
    mirror_gap: str | None = Field(
        None, description="above 1 degree, what the gap hides for a glossy specimen (a "
                          "narrower highlight is neither measured nor in a scan's "
                          "predicted_log_rmse), in words; a scan's dry run and result say "
                          "the same")
    lights: list[Device]
    sensors: list[Device]
    pairs: list[DesignPair]
    roughness: RoughnessInfo
    search: SearchInfo | None = Field(
        None, description="condition-number search statistics (designs it made)")
    greedy: GreedyInfo | None = Field(
        None, description="expected-error choice statistics (designs it made)")
    rig_config_toml: str = Field(
        description="[[lights]], [[sensors]] and pairs, to merge into a rig config (each device "
                    "still needs its driver settings); a colour design adds a [design] table "
                    "with its colour_instrument and colour_weight, a design weighted by the "
                    "renderings one with its render_mix")


class PresetInfo(BaseModel):
    name: str
    description: str
    n_pairs: int


def _finite(x: float) -> float | None:
    return float(x) if math.isfinite(x) else None


def describe(design: PairDesign, rotations: int,
             span_deg: float = DEFAULT_SPAN_DEG,
             colour: tuple[str, float] | None = None) -> DesignResult:
    """The API view of a :class:`~gonio.brdf.design.pairdesign.PairDesign`.

    ``colour``: the instrument and weight of a colour design, recorded in the fragment's
    ``[design]`` table so the rig config it goes into says so (docs/colour.md); otherwise a
    design weighted by the standard renderings records its ``render_mix`` there.
    """
    from gonio.config import DesignExpectation
    from gonio.rigdesign import design_fragment, dump_fragment

    bound = roughness_bound(design.cells, design.ph_lab, bound_angles(rotations, span_deg))
    # The fragment records what chose the pairs, as `gonio design -o` writes it: a colour
    # design's instrument and weight, or the renderings' weighting (docs/rig-config.md).
    record = (DesignExpectation(rotations=rotations, span_deg=span_deg, pairs=design.n_pairs,
                                colour_instrument=colour[0], colour_weight=colour[1])
              if colour is not None else
              DesignExpectation(rotations=rotations, span_deg=span_deg, pairs=design.n_pairs,
                                render_mix=float(design.cell_mix))
              if design.cell_mix else None)
    frag = design_fragment(design, record)
    lights = [Device(**d) for d in frag["lights"]]
    sensors = [Device(**d) for d in frag["sensors"]]
    cells = np.rad2deg(design.cells)
    ph = np.rad2deg(design.ph_lab) % 360.0
    pairs = [
        DesignPair(light=lights[a].name, sensor=sensors[b].name, theta_h_deg=float(c[0]),
                   theta_d_deg=float(c[1]), phi_d_deg=float(c[2]), phi_h_lab_deg=float(p))
        for (a, b), c, p in zip(design.pairs.tolist(), cells, ph, strict=True)
    ]
    search, greedy = design.search, design.greedy
    expected = design.expected_log_rmse
    gap = cells_gap_deg(design.cells)
    return DesignResult(
        name=design.name,
        n_pairs=design.n_pairs,
        condition_number=_finite(design.kappa),
        objective=design.objective,
        expected_log_rmse=None if expected is None else _finite(expected),
        fallback=design.fallback,
        colour_pairs=design.colour_pairs,
        render_mix=float(design.cell_mix),
        min_device_distance_deg=float(design.min_distance_deg),
        mirror_gap_deg=gap,
        mirror_gap=gap_note(gap),
        lights=lights,
        sensors=sensors,
        pairs=pairs,
        roughness=RoughnessInfo(rotations=rotations, span_deg=span_deg,
                                alpha_min=_finite(bound.alpha_min),
                                n_effective=float(bound.n_effective), degree=int(bound.degree),
                                cap_deg=float(bound.cap_deg)),
        search=None if search is None else SearchInfo(
            neighbourhoods=search.neighbourhoods, evaluations=search.evaluations,
            seconds=search.seconds),
        greedy=None if greedy is None else GreedyInfo(
            candidates=greedy.candidates, evaluations=greedy.evaluations,
            mount_checks=greedy.mount_checks, first=greedy.first, seconds=greedy.seconds),
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
            objective=request.objective, rotations=request.rotations,
            span_deg=request.span_deg, colour=request.colour(), **request.cells_weighting(),
        )
    else:
        assert request.lights is not None and request.sensors is not None
        design = with_expected_error(basis, design_product_rig(
            basis, request.lights, request.sensors, constraints, h=request.neighbourhood,
            starts=request.starts, seed=request.seed, time_limit_s=request.time_limit_s,
        ), request.rotations, request.span_deg)
    colour = (None if request.colour_instrument is None else
              (canonical_instrument(request.colour_instrument), request.colour_weight))
    return describe(design, request.rotations, request.span_deg, colour)


def evaluate_preset(basis: BasisLike, preset: Preset, rotations: int,
                    span_deg: float = DEFAULT_SPAN_DEG) -> DesignResult:
    """An industrial geometry evaluated like an optimised one (V&F Table 1)."""
    wi, wo = preset.directions()
    n = preset.n_pairs
    design = geometry_design(basis, preset.name, wi, wo, np.stack([np.arange(n)] * 2, axis=1))
    return describe(with_expected_error(basis, design, rotations, span_deg), rotations, span_deg)
