"""``gonio rig``: work on a rig config file.

``gonio rig apply-design geometry.toml rig.toml`` merges a design fragment (from
``gonio design -o``) into a rig config: the design's lights and sensors take their places, its
pairs become the rig's pairs (rules in :func:`gonio.rigdesign.apply_design`). The rig config is
rewritten in place (comments are not kept; the previous file is saved as ``rig.toml.bak``)
unless ``-o`` names another file.
"""

from __future__ import annotations

import argparse
import shutil
import tomllib
from pathlib import Path
from typing import Any

from gonio.cli import UsageError


def register(subparsers: Any) -> None:
    """Add the ``rig`` sub-command."""
    p = subparsers.add_parser("rig", help="edit a rig config: apply a design")
    sub = p.add_subparsers(dest="rig_command", metavar="ACTION", required=True)
    a = sub.add_parser(
        "apply-design",
        help="put a design's lights, sensors and pairs into a rig config",
        description="Merge a design fragment (gonio design -o) into a rig config: devices of "
        "the same name move to the design's directions and keep their hardware settings, new "
        "ones copy the last device's settings with the next free Modbus device id, and the "
        "design's pairs become the measured pairs. See docs/rig-config.md.",
    )
    a.add_argument("design", type=Path, help="design fragment TOML (gonio design -o)")
    a.add_argument("rig", type=Path, help="rig config TOML to update")
    a.add_argument("-o", "--output", type=Path, default=None,
                   help="write the merged config here instead of rewriting RIG")
    a.set_defaults(func=_apply_design)


def _apply_design(args: argparse.Namespace) -> int:
    from gonio.config import ConfigError
    from gonio.rigdesign import apply_design, load_fragment

    design = load_fragment(args.design)  # ConfigError is a ValueError: one clear line
    try:
        data = tomllib.loads(args.rig.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise UsageError(f"rig config {args.rig} does not exist; start from "
                         "deploy/rig.example.toml") from None
    except tomllib.TOMLDecodeError as exc:
        raise UsageError(f"{args.rig}: not valid TOML: {exc}") from None
    try:
        merged, notes = apply_design(data, design, args.rig.name)
    except ConfigError as exc:
        raise UsageError(f"the design does not fit {args.rig}:\n{exc}") from None
    import tomli_w

    out = args.output or args.rig
    if out == args.rig:
        shutil.copyfile(args.rig, args.rig.with_name(args.rig.name + ".bak"))
    out.write_text(tomli_w.dumps(merged), encoding="utf-8")
    for note in notes:
        print(f"note: {note}")
    n = len(design.pair_names())
    saved = f" (previous version in {args.rig.name}.bak)" if out == args.rig else ""
    print(f"wrote {out}: {len(design.lights)} lights, {len(design.sensors)} sensors, {n} pairs "
          f"from {args.design}{saved}")
    return 0
