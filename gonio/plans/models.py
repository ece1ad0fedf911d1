"""Scan plans as serializable data: the three kinds, their settings, and parsing from JSON.

A plan says *what* to measure (which pairs, at which stage angles, with which exposure); the
engine (:mod:`gonio.engine`) says *how*. Plans are pydantic models, so they travel unchanged
through the REST API, the job store (as JSON) and result files.

Three kinds, told apart by ``kind``:

``uniform``
    The rig's pairs at ``rotations`` stage angles ``start_deg + k span_deg / rotations``:
    over half a turn by default (``span_deg = 180``; a twofold-symmetric specimen reads the
    same turned by half a turn, so the angles show every pair twice as many distinct azimuths
    as over a full turn, docs/science.md 7.4), or a full turn (360).
``adaptive``
    Start with ``initial_rotations`` uniform angles over ``span_deg``, then refine by
    ``rule``: ``posterior`` (default) adds the angles where the joint fit's posterior expects
    the error to fall most, while that fall is at least ``min_gain`` (docs/science.md 7.3);
    ``vf`` (V&F Sec. 6 / math.md 9) adds the midpoints around every angle where leave-one-out
    periodic PCHIP mispredicts a pair's value by more than ``threshold``
    (:mod:`gonio.plans.adaptive`). Rounds repeat until the rule stops, the sample budget is
    spent, or a new step would be finer than ``min_step_deg``.
``calibration``
    A white reference of known albedo (a Lambertian reference has ``f = albedo / pi``) at a few
    angles; the result is each pair's factor from sensor counts to BRDF (:mod:`gonio.calibration`).

Angles are degrees here (plans are user-facing). A plan's angles are specimen rotations in
``[0, 360)``. Plans stored before ``span_deg`` existed covered a full turn and are read so
(:func:`parse_stored_plan`). Every check a plan can fail raises :class:`PlanError` before
anything moves.
"""

from __future__ import annotations

from typing import Annotated, Any, ClassVar, Literal

from pydantic import AfterValidator, BaseModel, BeforeValidator, Field, model_validator

# The arcs a plan may cover and its default (half a turn) are the numerical core's: one
# definition, which the design tools and the API share.
from gonio.brdf.reconstruction.samples import DEFAULT_SPAN_DEG, SPANS_DEG
from gonio.fields import FINITE, Count, Text
from gonio.hal import PairSpec


class PlanError(ValueError):
    """A plan that cannot run on this rig; the message says what is wrong and what to do."""


MAX_ROTATIONS = 3600
"""Most stage angles one job may measure (0.1 degree steps; V&F use 8 to 72). Caps the work
a plan costs to check and time, and the readings an adaptive plan can grow to."""


class ExposureSettings(BaseModel):
    """How each reading is taken.

    ``exposure_s`` is the integration time of one exposure, ``averages`` how many exposures are
    averaged; ``light_settle_s`` is the wait after switching a light on (lamp warm-up and
    stabilisation). ``dark`` chooses when sensors are read with every light off: at every stage
    angle (tracks drifting dark signal, costs one exposure per angle), once at the start, or
    never (the sensors subtract their own dark).
    """

    model_config = FINITE

    exposure_s: float = Field(default=0.01, gt=0, description="seconds per exposure")
    averages: Count = Field(default=1, ge=1, le=1000)
    light_settle_s: float = Field(default=0.05, ge=0, le=60)
    dark: Literal["every_angle", "once", "none"] = "once"


class FaultPolicy(BaseModel):
    """How the engine suspends and retries on recoverable device faults.

    After a fault the engine waits ``retry_delay_s``, tries the device's recovery (clear
    faults, reconnect, re-check the lamp), waits ``resume_settle_s`` and repeats the
    interrupted angle. More than ``max_retries`` consecutive failures at one angle fail the job,
    except for a device that does not answer at all: the job then stays suspended and the
    device is tried every ``retry_delay_s`` until it answers (then the angle is repeated from
    the checkpoint) or ``wait_for_device_s`` have passed since the first fault.
    """

    model_config = FINITE

    max_retries: Count = Field(default=5, ge=0, le=100)
    retry_delay_s: float = Field(default=1.0, ge=0, le=3600)
    wait_for_device_s: float = Field(
        default=600.0, ge=0, le=86400,
        description="when a device stops answering (unplugged cable, power cut) and the "
                    "retries are spent, keep the job suspended and try the device every "
                    "retry_delay_s until it answers again, up to this many seconds from the "
                    "first fault; then the job fails. 0: fail after max_retries",
    )
    resume_settle_s: float = Field(default=0.5, ge=0, le=3600)
    saturation: Literal["suspend", "record"] = Field(
        default="suspend",
        description="'suspend': a saturated reading is a fault and the angle is retried; "
        "'record': keep it, flagged saturated",
    )


def _check_start(value: float) -> float:
    if not 0.0 <= value < 360.0:
        raise ValueError(
            f"start_deg is a specimen angle in [0, 360) degrees; {value:g} is outside (it is "
            f"not wrapped silently). For the same angle write {value % 360.0:g}"
        )
    return value




def _check_span(value: object) -> object:
    # Before the type check, so any wrong value (a string too) gets the sentence on both arcs.
    if isinstance(value, bool) or value not in SPANS_DEG:
        raise ValueError(
            f"span_deg is the arc the uniform stage angles cover: 180 (half a turn, the "
            f"default: a twofold-symmetric specimen, as brushed, woven and most coated ones are, "
            f"reads the same turned by half a turn) or 360 (a full turn, for a specimen without "
            f"that symmetry, e.g. a pile with a lean or a blazed structure); got {value!r}")
    return value


SpanDeg = Annotated[
    float,
    BeforeValidator(_check_span),
    Field(description="arc of the uniform stage angles, degrees: 180 (half a turn; a "
                      "twofold-symmetric specimen reads the same turned by half a turn, so the "
                      "angles see twice as many distinct azimuths) or 360 (a full turn, for "
                      "specimens without twofold symmetry)",
          json_schema_extra={"enum": list(SPANS_DEG)}),
]


DEFAULT_MIN_GAIN = 2e-5
"""Default ``min_gain`` of adaptive plans: ``gonio.brdf.reconstruction.posterior.REFINE_GAIN``
(a test keeps the two equal; the plans do not import the numerical core for one number)."""
DEFAULT_MAX_ROTATIONS = 16
"""Default ``max_rotations`` of adaptive plans with the posterior rule: the rule was chosen and
measured against uniform 16 rotations with at most 16 stage angles (docs/science.md 7.3), so
a job stops there and the dry run's bound is what the rule can really do."""
RULES = ("posterior", "vf")
"""The refinement rules of adaptive plans (docs/science.md 7.3)."""


def _check_rule(value: object) -> object:
    # Before the type check, so an unknown rule gets one sentence that names both rules.
    if value not in RULES:
        raise ValueError(
            f"rule must be 'posterior' (add the stage angles where the joint fit's expected "
            f"log_rmse falls most; the default) or 'vf' (V&F Sec. 6: midpoints where PCHIP "
            f"mispredicts a reading by more than threshold); got {value!r}")
    return value


def _check_min_gain(value: float) -> float:
    if not value > 0.0:
        raise ValueError(
            f"min_gain is the least drop of the self-estimated log_rmse one more stage angle "
            f"must buy, a number > 0; got {value:g}. The default {DEFAULT_MIN_GAIN:g} was "
            f"chosen on held-out materials; larger stops refining sooner (fewer readings), "
            f"smaller refines more")
    return value


Rule = Annotated[
    Literal["posterior", "vf"],
    BeforeValidator(_check_rule),
    Field(description="posterior: add the stage angles where the joint fit's expected "
                      "log_rmse falls most, stop when the best lowers the self-estimated "
                      "log_rmse by less than min_gain "
                      "(needs the basis; an engine without one uses vf); vf: V&F Sec. 6, "
                      "midpoints where PCHIP mispredicts a reading by more than threshold"),
]
MinGain = Annotated[
    float,
    AfterValidator(_check_min_gain),
    Field(description="posterior rule: least drop of the self-estimated log_rmse "
                      "one more stage angle must buy, > 0 "
                      "(gonio.brdf.reconstruction.posterior.REFINE_GAIN)",
          # The bounds in the schema for clients; the check itself is _check_min_gain's, so
          # the message says what the number means and what to do.
          json_schema_extra={"exclusiveMinimum": 0.0}),
]


ARC_MODES = ("fixed", "auto")
"""How a plan's arc is chosen: ``fixed`` (its ``span_deg``, 180 or 360, forces either) or
``auto`` (the first round tests twofold symmetry, :mod:`gonio.plans.arc`)."""
DEFAULT_ARC_NOISE = 0.01
"""Default relative noise of one reading that the arc test scales by: 1 %, the simulated
sensors' level at a few thousand counts (sim/specimen.py) and the noise the designs assume."""


def _check_arc(value: object) -> object:
    # Before the type check, so any wrong value gets the sentence on both modes.
    if value not in ARC_MODES:
        raise ValueError(
            f"arc is 'fixed' (span_deg decides: 180 half a turn, 360 a full turn) or 'auto' "
            f"(the first round reads opposite stage angles and tests twofold symmetry, then the "
            f"scan continues over half a turn if the specimen has it, else over a full turn); "
            f"got {value!r}")
    return value


ArcMode = Annotated[
    Literal["fixed", "auto"],
    BeforeValidator(_check_arc),
    Field(description="fixed: span_deg is the arc (180 or 360 forces either); auto: the first "
                      "round reads the half-turn angles plus the first one's opposite (and the "
                      "one a quarter turn on when the pairs lie in nearly one plane), tests "
                      "twofold symmetry against arc_noise (docs/science.md 7.4), and the scan "
                      "continues over half a turn if the specimen has it, else over a full turn "
                      "(span_deg must then be 180, the default)"),
]
ArcNoise = Annotated[
    float,
    Field(gt=0, lt=1, description="arc auto: the rig's relative noise of one reading (0.01: "
                                  "1 %, the simulated sensors'); the symmetry test's scale. "
                                  "Larger: fewer specimens called asymmetric"),
]


class _ArcChoice(BaseModel):
    """The arc settings of the plan kinds that reconstruct (uniform, adaptive)."""

    model_config = FINITE

    arc: ArcMode = "fixed"
    arc_noise: ArcNoise = DEFAULT_ARC_NOISE

    @model_validator(mode="after")
    def _auto_needs_half(self) -> _ArcChoice:
        if self.arc == "auto" and getattr(self, "span_deg", 180.0) != 180.0:
            raise ValueError(
                "arc 'auto' chooses the arc itself (half a turn for a twofold-symmetric "
                "specimen, else a full turn) and needs span_deg 180 (the default); span_deg "
                "360 forces a full turn: drop arc 'auto' or span_deg 360")
        return self


StartDeg = Annotated[
    float,
    AfterValidator(_check_start),
    Field(description="first specimen angle, degrees in [0, 360); values outside are refused, "
                      "not wrapped"),
]


class _PlanBase(BaseModel):
    model_config = FINITE

    specimen: Text = Field(default="specimen", min_length=1, max_length=200)
    pairs: list[PairSpec] | None = Field(
        default=None, description="pairs to measure; null means every pair of the rig"
    )
    exposure: ExposureSettings = Field(default_factory=ExposureSettings)
    faults: FaultPolicy = Field(default_factory=FaultPolicy)
    backlash_deg: float = Field(
        default=0.0,
        ge=0,
        le=90,
        description="extra overshoot below an angle approached from above (0: rely on the "
        "stage driver's own approach setting)",
    )
    stop_queue_on_failure: bool = False

    # The behaviour of each kind, asked of the plan rather than read off its class. Class
    # attributes, not fields: a plan's JSON and the API schema hold its settings only.
    finishing: ClassVar[Literal["reconstruction", "calibration"]] = "reconstruction"
    """What finishing the measured job makes (:mod:`gonio.finishing`): a reconstructed BRDF,
    or the rig's calibration factors."""
    refines: ClassVar[bool] = False
    """Whether the job adds stage angles after its first round (adaptive refinement)."""
    rotations_field: ClassVar[str] = "rotations"
    """The setting that gives the first round's number of stage angles (named in errors)."""

    def first_rotations(self) -> int:
        """Number of stage angles of the first round (``start_deg + k span / r``)."""
        return int(getattr(self, self.rotations_field))

    def arc_mode(self) -> Literal["fixed", "auto"]:
        """``auto`` when the first round tests twofold symmetry (:mod:`gonio.plans.arc`)."""
        return "auto" if getattr(self, "arc", "fixed") == "auto" else "fixed"

    def first_span_deg(self) -> float:
        """Arc (degrees) of the first round's uniform angles: the plan's ``span_deg``, or a
        full turn for kinds without one (a calibration's white reference)."""
        return float(getattr(self, "span_deg", 360.0))


class UniformPlan(_ArcChoice, _PlanBase):
    """n pairs x r uniformly spaced stage angles."""

    kind: Literal["uniform"] = "uniform"
    rotations: Count = Field(default=8, description="number of stage angles r")
    start_deg: StartDeg = 0.0
    span_deg: SpanDeg = DEFAULT_SPAN_DEG


class AdaptivePlan(_ArcChoice, _PlanBase):
    """Uniform start, then refinement rounds (math.md 9; docs/science.md 7.3)."""

    kind: Literal["adaptive"] = "adaptive"
    refines = True
    rotations_field = "initial_rotations"
    initial_rotations: Count = Field(
        default=4, description="r0 uniform angles of the first round; default 4 with the "
        "posterior rule (chosen on held-out materials, docs/science.md 7.3), 8 with vf "
        "(V&F's start)")
    rule: Rule = "posterior"
    threshold: float = Field(default=0.1, gt=0,
                             description="vf rule: relative error e (0.1 = 10 %)")
    min_gain: MinGain = DEFAULT_MIN_GAIN
    max_rotations: Count | None = Field(
        default=DEFAULT_MAX_ROTATIONS, gt=0, le=MAX_ROTATIONS,
        description="most stage angles the job measures, the first round's included; default "
        f"{DEFAULT_MAX_ROTATIONS} with the posterior rule (the budget it was chosen for, "
        "docs/science.md 7.3), none with vf (V&F: until the rule stops); null: only the "
        f"per-job limit of {MAX_ROTATIONS}")
    max_samples: Count | None = Field(
        default=None, gt=0, description="budget of pair readings (pairs x angles); null = none"
    )
    min_step_deg: float | None = Field(
        default=None, gt=0, description="finest angular step; null = the stage resolution"
    )
    max_rounds: Count = Field(default=6, ge=1, le=20)
    start_deg: StartDeg = 0.0
    span_deg: SpanDeg = Field(
        default=DEFAULT_SPAN_DEG, description="arc of the first round's uniform angles and of "
        "the refinement, degrees: 180 (default with the posterior rule) or 360 (default with "
        "vf, V&F's full turn)")

    @model_validator(mode="before")
    @classmethod
    def _vf_defaults(cls, data: object) -> object:
        # The defaults of the first round, the cap and the arc depend on the rule: the
        # posterior rule refines from 4 angles up to 16 over half a turn, V&F's from their 8
        # over a full turn until it stops (explicit settings are kept as given).
        if isinstance(data, dict) and data.get("rule") == "vf":
            vf: dict[str, object] = {"initial_rotations": 8, "max_rotations": None}
            if data.get("arc") != "auto":  # auto chooses the arc; it starts over half a turn
                vf["span_deg"] = 360.0
            return {**{k: v for k, v in vf.items() if k not in data}, **data}
        return data


class CalibrationPlan(_PlanBase):
    """A white reference of known albedo measured at a few angles."""

    kind: Literal["calibration"] = "calibration"
    finishing = "calibration"
    reference_albedo: float = Field(gt=0, le=1, description="hemispherical albedo of the reference")
    reference_name: Text = Field(default="white reference", min_length=1, max_length=200)
    rotations: Count = Field(default=4, description="angles averaged to even out the reference")
    start_deg: StartDeg = 0.0

    @model_validator(mode="before")
    @classmethod
    def _named_after_its_reference(cls, data: Any) -> Any:
        # The job list shows ``specimen``: a calibration queued with reference_name
        # "spectralon" and no specimen was listed as "specimen".
        if isinstance(data, dict) and "specimen" not in data:
            name = data.get("reference_name")
            return {**data, "specimen": name if isinstance(name, str) and name.strip()
                    else "white reference"}
        return data


Plan = Annotated[UniformPlan | AdaptivePlan | CalibrationPlan, Field(discriminator="kind")]


class _PlanHolder(BaseModel):
    plan: Plan


def parse_plan(data: object) -> UniformPlan | AdaptivePlan | CalibrationPlan:
    """Validate a plan from JSON-like data (``dict`` or JSON ``str``); raises :class:`PlanError`."""
    from pydantic import ValidationError

    try:
        if isinstance(data, str | bytes):
            return _PlanHolder.model_validate_json(b'{"plan": ' + _as_bytes(data) + b"}").plan
        return _PlanHolder.model_validate({"plan": data}).plan
    except ValidationError as exc:
        problems = "; ".join(
            f"{'.'.join(str(p) for p in e['loc'][1:]) or 'plan'}: {e['msg']}" for e in exc.errors()
        )
        raise PlanError(f"invalid plan: {problems}") from None


#: Plan fields added after plans were first stored, each with the value that keeps an older
#: stored plan's meaning: a job queued (or interrupted) before an upgrade runs as submitted.
#: ``max_rotations`` arrived with a default of 16 for the posterior rule; before, such a job was
#: bounded only by the per-job limit. ``span_deg`` arrived with a default of half a turn; before,
#: every plan's angles covered a full turn.
_ADDED_SINCE_STORED: dict[str, dict[str, object]] = {
    "adaptive": {"max_rotations": None, "span_deg": 360.0},
    "uniform": {"span_deg": 360.0},
}


def parse_stored_plan(data: dict[str, Any]) -> UniformPlan | AdaptivePlan | CalibrationPlan:
    """Validate a plan read back from the job store; raises :class:`PlanError`.

    Stored plans are complete dumps (``model_dump``), so a field missing from one was added to
    the model after it was stored; it takes the value that keeps the plan's meaning at
    submission (:data:`_ADDED_SINCE_STORED`), not today's default. Requests use
    :func:`parse_plan`.
    """
    if isinstance(data, dict):
        added = _ADDED_SINCE_STORED.get(str(data.get("kind")), {})
        data = {**{k: v for k, v in added.items() if k not in data}, **data}
    return parse_plan(data)


def _as_bytes(s: str | bytes) -> bytes:
    return s.encode() if isinstance(s, str) else s


AnyPlan = UniformPlan | AdaptivePlan | CalibrationPlan
