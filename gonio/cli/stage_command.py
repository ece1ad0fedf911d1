"""``gonio stage``: drive the rotation stage by hand, without the daemon.

For commissioning (turn the holder until its reference mark lies on the lab x axis, then
``home`` to make that 0 deg) and for checking a new rig's stage wiring and limits. The daemon's
``POST /api/v1/rig/stage`` does the same while it owns the rig.
"""

from __future__ import annotations

import argparse
import asyncio
import sys
from typing import Any

from gonio.cli import UsageError


def register(subparsers: Any) -> None:
    """Add the ``stage`` sub-command."""
    p = subparsers.add_parser(
        "stage",
        help="move, zero or inspect the rotation stage of a rig config",
        description=__doc__.split("\n\n")[1].replace("\n", " ") if __doc__ else None,
    )
    p.add_argument("--rig", required=True, help="rig config TOML")
    p.add_argument("action", choices=("status", "move", "home", "stop", "clear-faults"))
    p.add_argument("angle_deg", nargs="?", type=float, help="target of 'move', degrees")
    p.set_defaults(func=run)


async def _run(args: argparse.Namespace) -> str:
    from gonio.config import load_rig_config
    from gonio.drivers.factory import build_stage

    config = load_rig_config(args.rig)
    stage = build_stage(config.stage)
    target: float = 0.0
    if args.action == "move":
        if args.angle_deg is None:
            raise UsageError("'move' needs a target angle in degrees, e.g. gonio stage move 90")
        if not stage.limits.contains(args.angle_deg):
            raise UsageError(
                f"{args.angle_deg:g} deg is outside the travel limits "
                f"[{stage.limits.min_deg:g}, {stage.limits.max_deg:g}] of {args.rig} "
                "(stage.min_deg / stage.max_deg)"
            )
        target = float(args.angle_deg)
    elif args.angle_deg is not None:
        raise UsageError(f"'{args.action}' takes no angle")
    await stage.connect()
    try:
        if args.action == "move":
            await stage.move_to(target)
        elif args.action == "home":
            await stage.home()
        elif args.action == "stop":
            await stage.stop()
        elif args.action == "clear-faults":
            await stage.clear_faults()
        st = await stage.status()
    finally:
        await stage.close()
    faults = ", ".join(st.faults) if st.faults else "none"
    return (f"stage at {st.position_deg:.3f} deg, {'moving' if st.moving else 'idle'}, "
            f"{'homed' if st.homed else 'not homed'}, faults: {faults}")


def run(args: argparse.Namespace) -> int:
    from gonio.hal import DeviceFault

    try:
        print(asyncio.run(_run(args)))
    except DeviceFault as exc:
        print(f"gonio stage: stage fault: {exc}", file=sys.stderr)
        return 1
    return 0
