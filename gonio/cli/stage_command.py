"""``gonio stage``: drive the rotation stage by hand, on a rig config or through a daemon.

For commissioning (turn the holder until its reference mark lies on the lab x axis, then
``home`` to make that 0 deg), for loading specimens and for checking a new rig's stage wiring
and limits. With ``--rig`` it opens the stage itself, which is refused while another program (a
daemon, a scan) owns the rig; with ``--daemon URL`` it asks that daemon to do it
(``POST /api/v1/rig/stage``), which is the way to move a stage the daemon owns.
"""

from __future__ import annotations

import argparse
import math
import sys
from typing import Any

from gonio.cli import UsageError
from gonio.cli.daemon_client import DaemonClient, DaemonRefused, add_daemon_options


def register(subparsers: Any) -> None:
    """Add the ``stage`` sub-command."""
    p = subparsers.add_parser(
        "stage",
        help="move, zero or inspect the rotation stage of a rig config or a running daemon",
        description=__doc__.split("\n\n")[1].replace("\n", " ") if __doc__ else None,
    )
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--rig", help="rig config TOML: open the stage directly")
    src.add_argument("--daemon", metavar="URL",
                     help="a running daemon's address (e.g. http://127.0.0.1:8600): act through "
                          "its API")
    add_daemon_options(p)
    p.add_argument("action", choices=("status", "move", "home", "stop", "clear-faults"))
    p.add_argument("angle_deg", nargs="?", type=float, help="target of 'move', degrees")
    p.set_defaults(func=run)


def _check_args(args: argparse.Namespace) -> None:
    if args.action == "move" and args.angle_deg is None:
        raise UsageError("'move' needs a target angle in degrees, e.g. gonio stage move 90")
    if args.action != "move" and args.angle_deg is not None:
        raise UsageError(f"'{args.action}' takes no angle")
    if args.action == "move" and not math.isfinite(args.angle_deg):
        # Through a daemon a NaN reached the JSON encoder ("Out of range float values are
        # not JSON compliant"); no stage has such a target.
        raise UsageError(f"'move' needs a finite angle in degrees, got {args.angle_deg}; "
                         "e.g. gonio stage move 90")


def describe(position_deg: float, moving: bool, homed: bool, faults: list[str] | tuple[str, ...]
             ) -> str:
    """The one-line stage report both paths print; a position beyond one turn also gives the
    specimen's angle (position mod 360, what plans and plots use)."""
    turned = ("" if 0 <= position_deg < 360
              else f" (specimen at {position_deg % 360:.3f} deg)")
    return (f"stage at {position_deg:.3f} deg{turned}, {'moving' if moving else 'idle'}, "
            f"{'homed' if homed else 'not homed'}, faults: {', '.join(faults) or 'none'}")


async def _run(args: argparse.Namespace) -> str:
    from gonio.config import load_rig_config
    from gonio.drivers.factory import build_stage
    from gonio.hal import status_at_rest

    config = load_rig_config(args.rig)
    stage = build_stage(config.stage)
    target: float = 0.0
    if args.action == "move":
        if not stage.limits.contains(args.angle_deg):
            raise UsageError(
                f"{args.angle_deg:g} deg is outside the travel limits "
                f"[{stage.limits.min_deg:g}, {stage.limits.max_deg:g}] of {args.rig} "
                "(stage.min_deg / stage.max_deg)"
            )
        target = float(args.angle_deg)
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
        # Report where the stage ends up, not the ringing of the command just sent.
        st = await status_at_rest(stage)
    finally:
        await stage.close()
    return describe(st.position_deg, st.moving, st.homed, st.faults)


def _through_daemon(args: argparse.Namespace) -> str:
    with DaemonClient(args.daemon, args.api_key) as client:
        if args.action == "status":
            st = client.request("GET", "/api/v1/rig/stage")
        else:
            body: dict[str, Any] = {"action": args.action.replace("-", "_")}
            if args.action == "move":
                body["angle_deg"] = float(args.angle_deg)
            st = client.request("POST", "/api/v1/rig/stage", json=body)
    text = describe(float(st["position_deg"]), bool(st["moving"]), bool(st["homed"]),
                    list(st.get("faults", [])))
    if st.get("note"):
        # A move or home cut short by a stop from elsewhere (the page's Stop): not where it
        # was asked to go, so not a success for a script.
        raise StoppedShort(f"{args.action} {st['note']}; {text}")
    return text


class StoppedShort(Exception):
    """A stage command through a daemon that a stop command cut short (the answer's note)."""


def run(args: argparse.Namespace) -> int:
    import asyncio

    from gonio.hal import DeviceFault, DeviceInUse

    _check_args(args)
    try:
        print(_through_daemon(args) if args.daemon else asyncio.run(_run(args)))
    except DeviceInUse as exc:
        # The refusal names the daemon's address when it has one (gonio.locks.advertise_url).
        text = str(exc)
        if "--daemon http" not in text:
            text += (f" (e.g. gonio stage --daemon URL {args.action}, URL being the address "
                     "'gonio serve' printed)")
        raise UsageError(text) from None
    except DeviceFault as exc:
        print(f"gonio stage: stage fault: {exc}", file=sys.stderr)
        return 1
    except StoppedShort as exc:
        print(f"gonio stage: {exc}", file=sys.stderr)
        return 1
    except DaemonRefused as exc:
        if exc.status == 503:  # the daemon's stage reported a fault: as the local path
            print(f"gonio stage: stage fault: {exc}", file=sys.stderr)
            return 1
        raise
    return 0
