"""``gonio sim``: run a whole simulated rig and print the rig config that points at it.

The simulators run until Ctrl-C (or ``--duration`` seconds); meanwhile the daemon, a script or
the tests use the printed config as if it were a real rig. ``--geometry geometry.toml`` mounts
the simulated lights and sensors where a design fragment (``gonio design -o``) puts them.

``gonio sim-place white|specimen --rig rig.toml`` does what a person does at a real rig before
a calibration and after it: it puts the white reference on the simulated stage, or the
specimen back (over Modbus, device id 247 of the simulator; see docs/rig-config.md).
"""

from __future__ import annotations

import argparse
import dataclasses
import tempfile
import time
from pathlib import Path
from typing import Any

from gonio.cli import UsageError, positive_float

NOISE_KEYS = {
    "read": "read_noise",
    "shot": "shot_gain",
    "dark": "dark_offset",
    "dark-rate": "dark_rate",
}


def register(subparsers: Any) -> None:
    """Add the ``sim`` sub-command."""
    p = subparsers.add_parser(
        "sim",
        help="run a simulated rig (stage, lights, sensors) and print its rig config",
        description=(
            "Start a simulated rig on this machine: a rotation stage on a pseudo-terminal or "
            "TCP port and Modbus TCP lights and sensors on 127.0.0.1, looking at a simulated "
            "specimen. Writes a rig config pointing at them and runs until Ctrl-C."
        ),
    )
    p.add_argument("--stage", choices=("dynamixel", "zaber"), default="dynamixel")
    p.add_argument(
        "--zaber-transport",
        choices=("pty", "tcp"),
        default="pty",
        help="how the simulated Zaber stage is reached (default: pty)",
    )
    p.add_argument(
        "--material",
        default=None,
        help="library material name, .npz BRDF table, or a spectral material read by 31-band "
        "sensors (solid-red-paint, metallic-blue-paint, brushed-copper, ...: docs/colour.md) "
        "(default: a brushed, anisotropic dielectric)",
    )
    p.add_argument(
        "--noise",
        default="default",
        help="'default', 'none', or key=value list of read, shot, dark, dark-rate "
        "(e.g. 'read=3,shot=0.5')",
    )
    p.add_argument(
        "--time-scale",
        type=positive_float,
        default=1.0,
        help="sim seconds per wall second for motion and exposures (default 1)",
    )
    p.add_argument(
        "--fault",
        action="append",
        default=[],
        metavar="SPEC",
        help="inject a fault from the start; repeatable (see 'faults' below)",
    )
    p.add_argument("--seed", type=int, default=0, help="seed of the sensor noise")
    add_modbus_port_option(p)
    p.add_argument(
        "--geometry",
        type=Path,
        default=None,
        metavar="TOML",
        help="mount the lights and sensors as in this design fragment (gonio design -o) and "
        "measure its pairs (default: 3 lights, 4 sensors, all 12 pairs)",
    )
    p.add_argument(
        "-o",
        "--output",
        type=Path,
        default=None,
        help="where to write the rig config (default: a temporary file); a file there is "
        "replaced only when an earlier gonio sim wrote it, or with --overwrite",
    )
    p.add_argument("--overwrite", action="store_true",
                   help="replace the file -o names even if gonio sim did not write it")
    p.add_argument(
        "--duration",
        type=float,
        default=None,
        help="stop after this many seconds instead of waiting for Ctrl-C",
    )
    from gonio.sim.faults import FAULT_HELP

    p.epilog = f"faults: {FAULT_HELP}"
    p.set_defaults(func=run)

    q = subparsers.add_parser(
        "sim-place",
        help="put the white reference or the specimen on a simulated rig's stage",
        description="Change what is on the stage of a running 'gonio sim' (what a person does "
        "at a real rig): 'white' before a white-reference calibration, 'specimen' after it, "
        "'show' to ask.",
    )
    q.add_argument("what", choices=("white", "specimen", "show"))
    q.add_argument("--rig", type=Path, required=True, help="rig config written by gonio sim -o")
    q.add_argument("--albedo", type=float, default=None,
                   help="albedo of the white reference (default 0.99)")
    q.set_defaults(func=place)


def add_modbus_port_option(parser: Any) -> None:
    """``--modbus-port N``: where the simulated lights and sensors listen."""
    parser.add_argument(
        "--modbus-port", type=int, default=0, metavar="PORT",
        help="TCP port of the simulated Modbus lights and sensors on 127.0.0.1 (default 0: "
        "any free port; choose one where a firewall allows only known ports)")


def start_sim_rig_or_say_why(start: Any, options: Any) -> Any:
    """``start(options)``, with a port that cannot be bound said in one line (a bad option is
    a ValueError that says itself)."""
    try:
        return start(options)
    except OSError as exc:
        raise UsageError(f"cannot start the simulated rig: {exc}") from None


def parse_noise(text: str) -> Any:
    """``--noise`` value -> NoiseModel or None; ``UsageError`` naming the bad part."""
    from gonio.sim.rig import ADC_FULL_SCALE
    from gonio.sim.specimen import NoiseModel

    if text == "none":
        return None
    base = NoiseModel(saturation=ADC_FULL_SCALE)
    if text == "default":
        return base
    changes: dict[str, float] = {}
    for part in text.split(","):
        key, sep, value = part.partition("=")
        if not sep or key.strip() not in NOISE_KEYS:
            raise UsageError(
                f"--noise: {part!r} is not key=value with key one of "
                f"{', '.join(NOISE_KEYS)} (or use 'default' / 'none')"
            )
        try:
            number = float(value)
        except ValueError:
            raise UsageError(f"--noise: {key}={value!r} is not a number") from None
        if number < 0:
            raise UsageError(f"--noise: {key} must be >= 0, got {number}")
        changes[NOISE_KEYS[key.strip()]] = number
    return dataclasses.replace(base, **changes)


def _refuse_foreign_config(out: Path) -> None:
    """Refuse to replace a file at ``out`` that no ``gonio sim`` wrote. The README's simulated
    session writes ``-o rig.toml``, the name a lab gives its own hand-edited config: that file
    was replaced without a word or a backup."""
    from gonio.wording import SIM_CONFIG_HEADER

    if out.is_dir():
        raise UsageError(f"-o {out} is a folder; name the rig config file to write")
    if not out.exists():
        return
    try:
        with out.open(encoding="utf-8", errors="replace") as f:
            first = f.readline()
    except OSError as exc:
        raise UsageError(f"-o {out} cannot be read ({exc.strerror or exc}); name another "
                         "file") from None
    if first != SIM_CONFIG_HEADER:
        raise UsageError(f"{out} exists and was not written by gonio sim (a lab's own rig "
                         "config?): nothing was replaced; give -o another file, or "
                         "--overwrite to replace it")


def run(args: argparse.Namespace) -> int:
    from gonio.sim.rig import SimRigOptions, start_sim_rig

    if args.duration is not None and args.duration < 0:
        raise UsageError(f"--duration must be >= 0, got {args.duration}")
    if args.output is not None and not args.overwrite:
        _refuse_foreign_config(args.output)
    with tempfile.TemporaryDirectory(prefix="gonio-sim-") as tmp:
        out = args.output if args.output is not None else Path(tmp) / "rig.toml"
        geometry: dict[str, Any] = {}
        if args.geometry is not None:
            from gonio.rigdesign import load_fragment

            design = load_fragment(args.geometry)  # ConfigError: one clear line
            geometry = {
                "lights": [(d.theta_deg, d.phi_deg) for d in design.lights],
                "light_names": [d.name for d in design.lights],
                "sensors": [(d.theta_deg, d.phi_deg) for d in design.sensors],
                "sensor_names": [d.name for d in design.sensors],
                "pairs": None if design.pairs == "all" else design.pair_names(),
            }
        options = SimRigOptions(
            **geometry,
            stage=args.stage,
            zaber_transport=args.zaber_transport,
            material=args.material,
            noise=parse_noise(args.noise),
            time_scale=args.time_scale,
            faults=args.fault,
            seed=args.seed,
            config_path=out,
            modbus_port=args.modbus_port,
        )
        with start_sim_rig_or_say_why(start_sim_rig, options) as sim:
            from gonio.cli.sim_session import write_sim_specimen

            # Scans of this rig in other processes record the true material (renderings).
            write_sim_specimen(sim)
            print(f"simulated rig running; rig config: {sim.config_path}", flush=True)
            lights = ", ".join(
                f"{x.name} ({x.theta_deg:g}, {x.phi_deg:g})" for x in sim.config.lights
            )
            sensors = ", ".join(
                f"{x.name} ({x.theta_deg:g}, {x.phi_deg:g})" for x in sim.config.sensors
            )
            print(f"stage: {args.stage} at {sim.config.stage.port}", flush=True)
            print(f"lights: {lights}\nsensors: {sensors}", flush=True)
            print(f"on the stage: {sim.describe_stage()} (change it with 'gonio sim-place "
                  f"white|specimen --rig {sim.config_path}')", flush=True)
            deadline = None if args.duration is None else time.monotonic() + args.duration
            try:
                while deadline is None or time.monotonic() < deadline:
                    time.sleep(0.05 if deadline is not None else 0.5)
            except KeyboardInterrupt:
                print("stopping the simulated rig", flush=True)
    return 0


def place(args: argparse.Namespace) -> int:
    """``gonio sim-place``: write the simulated specimen holder's register over Modbus."""
    from pymodbus.client import ModbusTcpClient
    from pymodbus.exceptions import ModbusException

    from gonio.config import load_rig_config
    from gonio.sim.rig import HOLDER_DEVICE_ID, WHITE_REFERENCE_ALBEDO

    albedo = WHITE_REFERENCE_ALBEDO if args.albedo is None else args.albedo
    if not 0 < albedo <= 1:
        raise UsageError(f"--albedo is the white reference's albedo, in (0, 1]; got {albedo:g}")
    if args.albedo is not None and args.what != "white":
        raise UsageError("--albedo goes with 'white'")
    cfg = load_rig_config(args.rig)
    bus = cfg.lights[0].modbus
    client = ModbusTcpClient(bus.host, port=bus.port, timeout=2, retries=0)
    not_sim = (f"no simulated rig answers at {bus.host}:{bus.port} (device id "
               f"{HOLDER_DEVICE_ID}); is 'gonio sim -o {args.rig}' running? On a real rig, put "
               "the reference or specimen on the stage by hand")
    try:
        if not client.connect():
            raise UsageError(not_sim)
        if args.what != "show":
            words = [1, round(albedo * 1000)] if args.what == "white" else [0]
            reply = client.write_registers(0, words, device_id=HOLDER_DEVICE_ID)
            if reply.isError():
                raise UsageError(f"the simulated rig refused: {reply}")
        state = client.read_holding_registers(0, count=2, device_id=HOLDER_DEVICE_ID)
        if state.isError():
            raise UsageError(not_sim)
    except ModbusException as exc:
        raise UsageError(f"{not_sim} ({exc})") from None
    finally:
        client.close()
    code, per_mille = state.registers
    held = (f"the white reference (albedo {per_mille / 1000:g})" if code == 1
            else "the specimen")
    print(f"the simulated stage holds {held}")
    return 0
