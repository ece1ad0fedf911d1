"""``gonio rig``: work on a rig config file, or on the rig it describes.

``gonio rig lights-off --rig rig.toml`` (or ``--config daemon.toml``) switches every lamp of the
rig off: the systemd unit runs it after the daemon exits for any reason (``ExecStopPost=``, see
deploy/gonio.service), so a lamp that was on when the daemon stopped, crashed or was killed
does not stay on until someone notices. It clears each light's ``on_coil`` and takes the rig's
endpoint locks like any other program, so it is refused while a live daemon owns the rig (ask
that daemon instead: ``POST /api/v1/rig/halt``, or stop it).

``gonio rig apply-design geometry.toml rig.toml`` merges a design fragment (from
``gonio design -o``) into a rig config: the design's lights and sensors take their places, its
pairs become the rig's pairs (rules in :func:`gonio.rigdesign.apply_design`). The rig config is
rewritten in place (comments are not kept; the previous file is saved as ``rig.toml.bak``)
unless ``-o`` names another file.
"""

from __future__ import annotations

import argparse
import shutil
import sys
from pathlib import Path
from typing import Any

from gonio.cli import UsageError
from gonio.wording import counted


def register(subparsers: Any) -> None:
    """Add the ``rig`` sub-command."""
    p = subparsers.add_parser("rig", help="edit a rig config (apply a design), or switch a "
                              "rig's lamps off")
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
    off = sub.add_parser(
        "lights-off", help="switch every lamp of a rig off (the systemd unit's ExecStopPost)",
        description="Clear every light's on-coil, one unreachable controller not stopping the "
        "others; refused while a live daemon owns the rig. The systemd unit runs it after the "
        "daemon exits for any reason.",
    )
    src = off.add_mutually_exclusive_group(required=True)
    src.add_argument("--rig", type=Path, help="rig config TOML")
    src.add_argument("--config", type=Path, metavar="DAEMON_TOML",
                     help="daemon config: its [paths] rig_config names the rig")
    off.set_defaults(func=_lights_off)


def _apply_design(args: argparse.Namespace) -> int:
    from gonio.config import ConfigError, read_toml
    from gonio.rigdesign import apply_design, load_fragment

    design = load_fragment(args.design)  # ConfigError is a ValueError: one clear line
    data = read_toml(args.rig, noun="rig config", example="deploy/rig.example.toml",
                     error=ConfigError)
    try:
        merged, notes = apply_design(data, design, args.rig.name)
    except ConfigError as exc:
        raise UsageError(f"the design does not fit {args.rig}:\n{exc}") from None
    import tomli_w

    out = args.output or args.rig
    in_place = out.resolve() == args.rig.resolve()  # also "-o ./rig.toml" or an absolute path
    if in_place:
        shutil.copyfile(args.rig, args.rig.with_name(args.rig.name + ".bak"))
    # A config gonio sim wrote keeps its first line, which lets a later 'gonio sim -o' on it
    # replace it (any other file it refuses without --overwrite).
    from gonio.wording import SIM_CONFIG_HEADER

    with args.rig.open(encoding="utf-8", errors="replace") as f:
        header = SIM_CONFIG_HEADER if f.readline() == SIM_CONFIG_HEADER else ""
    out.write_text(header + tomli_w.dumps(merged), encoding="utf-8")
    for note in notes:
        print(f"note: {note}")
    n = len(design.pair_names())
    saved = f" (previous version in {args.rig.name}.bak)" if in_place else ""
    print(f"wrote {out}: {counted(len(design.lights), 'light')}, "
          f"{counted(len(design.sensors), 'sensor')}, {counted(n, 'pair')} "
          f"from {args.design}{saved}")
    _simulated_rig_note(args, data, merged)
    return 0


def _simulated_rig_note(args: argparse.Namespace, before: dict[str, Any],
                        after: dict[str, Any]) -> None:
    """Say so when the design added devices to a rig config ``gonio sim`` wrote: the running
    simulator has only the devices it started with, so a scan on the new ones fails (with a
    Modbus exception from each missing device id)."""
    from gonio.cli.sim_session import sim_specimen_path

    def count(data: dict[str, Any]) -> int:
        return len(data.get("lights") or []) + len(data.get("sensors") or [])

    if count(after) <= count(before) or not sim_specimen_path(args.rig).is_file():
        return
    print(f"note: {args.rig} was written by 'gonio sim' ({sim_specimen_path(args.rig).name} "
          "beside it): the running simulator has only the devices it started with, so the "
          "ones added here do not answer; stop it and start 'gonio sim --geometry "
          f"{args.design} -o {args.rig}' for a simulated rig with the design's devices")


def _rig_config(args: argparse.Namespace) -> Any:
    from gonio.config import load_rig_config

    path = args.rig
    if path is None:
        from gonio.daemon import DaemonConfigError, load_daemon_config

        try:
            path = load_daemon_config(args.config).paths.rig_config
        except DaemonConfigError as exc:
            raise UsageError(str(exc)) from None
        if path is None:
            raise UsageError(f"{args.config} sets no [paths] rig_config; give --rig rig.toml")
    return load_rig_config(path)


async def lights_off(config: Any) -> dict[str, str | None]:
    """Clear every light's coil; ``{light: None if off, else why not}``.

    One unreachable controller does not stop the others from being switched off.

    Raises
    ------
    gonio.hal.DeviceInUse
        Another program owns one of the rig's Modbus endpoints.
    """
    from gonio.drivers.modbus import ModbusLight, ModbusPool
    from gonio.hal import DeviceFault, DeviceInUse

    pool = ModbusPool()
    out: dict[str, str | None] = {}
    for cfg in config.lights:
        light = ModbusLight(cfg, pool)
        try:
            await light.set_on(False)
            out[cfg.name] = None
        except DeviceInUse:
            raise
        except DeviceFault as exc:
            out[cfg.name] = str(exc)
        finally:
            await light.close()
    return out


def _lights_off(args: argparse.Namespace) -> int:
    import asyncio

    from gonio.hal import DeviceInUse

    config = _rig_config(args)
    try:
        results = asyncio.run(lights_off(config))
    except DeviceInUse as exc:
        raise UsageError(f"{exc}; a live daemon switches its own lamps off (POST "
                         "/api/v1/rig/halt stops a job, stopping the daemon ends it)") from None
    failed = {n: why for n, why in results.items() if why is not None}
    off = [n for n, why in results.items() if why is None]
    if off:
        print(f"lights off: {', '.join(off)}")
    for name, why in failed.items():
        print(f"gonio rig: {name} may still be on: {why}", file=sys.stderr)
    return 1 if failed else 0
