"""Design fragments: where a design puts lights and sensors, and merging that into a rig config.

``gonio design -o geometry.toml`` writes a *design fragment*, a TOML file with the same tables a
rig config uses for geometry (docs/file-formats.md)::

    pairs = "all"            # product rigs only; independent pairs use [[pairs]] tables below

    [[lights]]
    name = "L1"
    theta_deg = 32.5
    phi_deg = 110.0

    [[sensors]]
    name = "S1"
    theta_deg = 47.5
    phi_deg = 290.0

    [[pairs]]
    light = "L1"
    sensor = "S1"

    [design]                 # what the design expects of a scan (docs/science.md 7.1)
    expected_log_rmse = 0.0376
    rotations = 8
    span_deg = 180.0
    pairs = 10
    colour_instrument = "MA98"   # a colour design only (docs/colour.md)
    colour_weight = 100.0

It carries no hardware (Modbus addresses, register maps). :func:`apply_design` merges it into
a rig config (``gonio rig apply-design``), ``gonio sim --geometry`` mounts simulated devices
there, and ``gonio simulate-scan --pairs`` reads its pairs.
"""

from __future__ import annotations

import copy
import os
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any, Literal

import tomli_w
from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from gonio.config import ConfigError, DesignExpectation, parse_rig_config, read_toml

if TYPE_CHECKING:
    from gonio.brdf.design.pairs import PairDesign

__all__ = [
    "DesignDevice",
    "DesignFragment",
    "FragmentPair",
    "apply_design",
    "dump_fragment",
    "load_fragment",
    "parse_fragment",
]


class DesignDevice(BaseModel):
    """One light or sensor of a design: a name and a lab direction (degrees)."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    name: Annotated[str, Field(min_length=1, pattern=r"^[A-Za-z0-9_.-]+$")]
    theta_deg: Annotated[float, Field(ge=0, lt=90)]
    phi_deg: float


class FragmentPair(BaseModel):
    """One measured pair of a design fragment, by device names (the API's view of a designed
    pair, with its half/difference cell, is :class:`gonio.sampling_design.DesignPair`)."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    light: str
    sensor: str


class DesignFragment(BaseModel):
    """A design fragment, validated: devices with directions and the pairs to measure.

    Keys a full rig config has besides these (``rig``, ``stage``, ``calibration``, a device's
    ``modbus`` ...) are ignored when reading, so a rig config is also a valid fragment.
    """

    model_config = ConfigDict(extra="ignore", frozen=True)

    lights: Annotated[list[DesignDevice], Field(min_length=1)]
    sensors: Annotated[list[DesignDevice], Field(min_length=1)]
    pairs: Literal["all"] | Annotated[list[FragmentPair], Field(min_length=1)] = "all"
    #: What the design expects of a scan (``gonio design`` writes it when it has the held-out
    #: error); :func:`apply_design` carries it into the rig config.
    design: DesignExpectation | None = None

    @model_validator(mode="after")
    def _check(self) -> DesignFragment:
        names = [d.name for d in self.lights] + [d.name for d in self.sensors]
        dup = sorted({n for n in names if names.count(n) > 1})
        if dup:
            raise ValueError(f"device names repeat: {dup}")
        if isinstance(self.pairs, list):
            lights = {d.name for d in self.lights}
            sensors = {d.name for d in self.sensors}
            for k, p in enumerate(self.pairs):
                if p.light not in lights:
                    raise ValueError(f"pairs[{k}].light: no light named {p.light!r}")
                if p.sensor not in sensors:
                    raise ValueError(f"pairs[{k}].sensor: no sensor named {p.sensor!r}")
        return self

    def pair_names(self) -> list[tuple[str, str]]:
        """(light, sensor) names of the measured pairs, in order."""
        if self.pairs == "all":
            return [(a.name, b.name) for a in self.lights for b in self.sensors]
        return [(p.light, p.sensor) for p in self.pairs]

    def light(self, name: str) -> DesignDevice:
        return next(d for d in self.lights if d.name == name)

    def sensor(self, name: str) -> DesignDevice:
        return next(d for d in self.sensors if d.name == name)


def _tables(data: dict[str, Any], keys: Sequence[str]) -> dict[str, Any]:
    """Reduce each ``[[table]]`` entry to ``keys`` (for reading a rig config as a fragment)."""
    out = dict(data)
    for kind in ("lights", "sensors"):
        if isinstance(out.get(kind), list):
            out[kind] = [
                {k: v for k, v in d.items() if k in keys} if isinstance(d, dict) else d
                for d in out[kind]
            ]
    return out


def parse_fragment(data: dict[str, Any], source: str = "design fragment") -> DesignFragment:
    """Validate parsed TOML as a design fragment (or a rig config's geometry).

    Raises
    ------
    ConfigError
        One line per problem, starting with ``source``.
    """
    try:
        return DesignFragment.model_validate(_tables(data, ("name", "theta_deg", "phi_deg")))
    except ValidationError as exc:
        lines = []
        for err in exc.errors():
            loc = ".".join(str(p) for p in err["loc"] if "[" not in str(p) and p != "str")
            msg = str(err["msg"]).removeprefix("Value error, ")
            lines.append(f"{source}: {loc + ': ' if loc else ''}{msg}")
        raise ConfigError(
            "\n".join(dict.fromkeys(lines))
            + "\n(a design fragment has [[lights]] and [[sensors]] tables with name, theta_deg, "
            "phi_deg, [[pairs]] tables or pairs = \"all\", and optionally the [design] table "
            "gonio design writes; see docs/file-formats.md)"
        ) from None


def load_fragment(path: str | os.PathLike[str]) -> DesignFragment:
    """Read a design fragment file (``gonio design -o``); a rig config also reads as one.

    Raises
    ------
    ConfigError
        Missing file, not TOML, or not a fragment; the message names the file.
    """
    p = Path(path)
    data = read_toml(p, noun="design", example="the file 'gonio design -o' writes",
                     error=ConfigError)
    return parse_fragment(data, p.name)


def design_fragment(design: PairDesign,
                    expectation: DesignExpectation | None = None) -> dict[str, Any]:
    """Design fragment of a :class:`~gonio.brdf.design.pairdesign.PairDesign` (``gonio design
    -o``, the design API): ``lights``, ``sensors`` (name, theta_deg, phi_deg) and ``pairs``,
    and ``design`` (what it expects of a scan) when ``expectation`` is given.

    Independent pairs get one light and one sensor each (``L1``/``S1`` ...) and an explicit
    ``[[pairs]]`` list; a product rig uses ``pairs = "all"``.
    """
    def devices(prefix: str, deg: Any) -> list[dict[str, Any]]:
        return [
            {"name": f"{prefix}{k + 1}", "theta_deg": round(float(t), 4),
             "phi_deg": round(float(p) % 360.0, 4)}
            for k, (t, p) in enumerate(deg)
        ]

    out: dict[str, Any] = {}
    if design.name == "product":
        out["pairs"] = "all"
    else:
        out["pairs"] = [
            {"light": f"L{a + 1}", "sensor": f"S{b + 1}"} for a, b in design.pairs.tolist()
        ]
    out["lights"] = devices("L", design.lights_deg)
    out["sensors"] = devices("S", design.sensors_deg)
    if expectation is not None:
        # Without a held-out error the simulated scans' assumptions (noise, materials ...)
        # describe nothing: only the keys given are written.
        out["design"] = expectation.model_dump(
            mode="json", exclude_none=True,
            exclude_unset=expectation.expected_log_rmse is None)
    return out


def dump_fragment(fragment: dict[str, Any], header: str = "") -> str:
    """TOML text of a fragment dict, with ``[[lights]]``/``[[sensors]]``/``[[pairs]]`` tables.

    Arrays of tables are written as ``[[...]]`` sections (not inline arrays), so the text can
    be appended to a rig config or merged with :func:`apply_design`.
    """
    lines = [f"# {line}".rstrip() for line in header.splitlines()]
    if fragment.get("pairs") == "all":
        lines.append('pairs = "all"')
    for kind in ("lights", "sensors", "pairs"):
        entries = fragment.get(kind)
        if not isinstance(entries, list):
            continue
        for entry in entries:
            lines += ["", f"[[{kind}]]", tomli_w.dumps(entry).rstrip()]
    if isinstance(fragment.get("design"), dict):
        lines += ["", "[design]", tomli_w.dumps(fragment["design"]).rstrip()]
    return "\n".join(lines).lstrip("\n") + "\n"


def apply_design(
    rig: dict[str, Any], design: DesignFragment, source: str = "rig config"
) -> tuple[dict[str, Any], list[str]]:
    """Merge a design into a rig config's TOML data; returns the new data and notes for the user.

    Rules (docs/rig-config.md, "Applying a design"):

    * a design device whose name the rig has keeps that entry's hardware (Modbus, registers,
      channels ...) and takes the design's ``theta_deg`` / ``phi_deg``;
    * a design device the rig lacks is added as a copy of the rig's last device of the same
      kind, with the next free Modbus ``device_id`` on that host and port (a note says so:
      check it against the wiring);
    * rig devices the design does not name stay (a note lists them) but are in no pair;
    * ``pairs`` becomes the design's;
    * ``[[calibration.factors]]`` of pairs whose light or sensor moved, or that are no longer
      measured, are dropped (a factor folds in the geometry it was measured with);
    * ``[design]`` (what the design expects of a scan) becomes the design's; a design without
      one removes the rig's, which described another geometry (a note says so).

    Raises
    ------
    ConfigError
        The rig has no device of a kind to copy, or the merged config is invalid.
    """
    out = copy.deepcopy(rig)
    notes: list[str] = []
    moved: set[str] = set()
    for kind, devices in (("lights", design.lights), ("sensors", design.sensors)):
        entries = out.get(kind)
        if not isinstance(entries, list) or not entries or not all(
            isinstance(e, dict) for e in entries
        ):
            raise ConfigError(
                f"{source}: has no [[{kind}]] entries to take hardware settings from; start "
                "from deploy/rig.example.toml"
            )
        by_name = {str(e.get("name")): e for e in entries}
        for dev in devices:
            entry = by_name.get(dev.name)
            if entry is None:
                template = entries[-1]
                entry = copy.deepcopy(template)
                entry["name"] = dev.name
                bus = entry.get("modbus")
                if isinstance(bus, dict):
                    used = {
                        (str(e["modbus"].get("host")), int(e["modbus"].get("port", 502)),
                         int(e["modbus"].get("device_id", 1)))
                        for e in [*out["lights"], *out["sensors"]]
                        if isinstance(e.get("modbus"), dict)
                    }
                    host, port = str(bus.get("host")), int(bus.get("port", 502))
                    dev_id = int(bus.get("device_id", 1))
                    while (host, port, dev_id) in used and dev_id < 247:
                        dev_id += 1
                    bus["device_id"] = dev_id
                    where = f"device_id {dev_id} on {host}:{port}"
                else:
                    where = "its settings"
                notes.append(
                    f"{dev.name}: new {kind[:-1]}, hardware copied from {template.get('name')} "
                    f"with {where}; check it against the wiring"
                )
                entries.append(entry)
                by_name[dev.name] = entry
            if (entry.get("theta_deg"), entry.get("phi_deg")) != (dev.theta_deg, dev.phi_deg):
                moved.add(dev.name)
            entry["theta_deg"] = dev.theta_deg
            entry["phi_deg"] = dev.phi_deg
        named = {d.name for d in devices}
        extra = [n for n in by_name if n not in named]
        if extra:
            notes.append(
                f"{', '.join(extra)}: {kind} the design does not use; kept, but in no pair "
                "(remove them if they are not mounted)"
            )
    if design.pairs == "all":
        out["pairs"] = "all"
        if design.lights and (len(out["lights"]) > len(design.lights)
                              or len(out["sensors"]) > len(design.sensors)):
            # "all" would pull in the unused devices: list the design's pairs instead.
            out["pairs"] = [{"light": a, "sensor": b} for a, b in design.pair_names()]
    else:
        out["pairs"] = [{"light": a, "sensor": b} for a, b in design.pair_names()]
    cal = out.get("calibration")
    if isinstance(cal, dict) and isinstance(cal.get("factors"), list):
        keep_pairs = set(design.pair_names())
        kept = [
            f for f in cal["factors"]
            if (f.get("light"), f.get("sensor")) in keep_pairs
            and f.get("light") not in moved and f.get("sensor") not in moved
        ]
        dropped = len(cal["factors"]) - len(kept)
        if dropped:
            notes.append(
                f"dropped {dropped} calibration factor(s) of pairs that moved or are no longer "
                "measured; calibrate again on the white reference"
            )
        cal["factors"] = kept
    if design.design is not None:
        out["design"] = design.design.model_dump(mode="json", exclude_none=True)
    elif out.pop("design", None) is not None:
        notes.append("removed the rig's [design] table: it described another geometry, and "
                     "this design carries none (scans are then not compared with a design)")
    parse_rig_config(out, source)  # the merged config must load
    return out, notes
