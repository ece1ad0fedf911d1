"""Build a :class:`gonio.hal.Rig` of real drivers from a validated rig configuration.

This is the only place that knows which driver class serves which config section; the engine
and the API receive the finished ``Rig`` and see only :mod:`gonio.hal` interfaces. Nothing is
opened here: call ``await rig.connect()`` (or ``async with rig``).
"""

from __future__ import annotations

from typing import TypedDict

from gonio.config import RigConfig, StageConfig
from gonio.drivers.modbus import ModbusLight, ModbusPool, ModbusSensor
from gonio.hal import Light, Rig, Sensor, Stage, TravelLimits

__all__ = ["STAGE_NAME", "build_rig", "build_stage"]

STAGE_NAME = "stage"


class _StageKwargs(TypedDict):
    """Keyword arguments both stage drivers take alike."""

    limits: TravelLimits
    speed_dps: float
    accel_dps2: float
    settle_s: float
    approach: str
    backlash_deg: float
    move_timeout_s: float

"""Device name of the rig's stage in faults and logs."""


def build_stage(cfg: StageConfig) -> Stage:
    """The stage driver for ``[stage]`` (Dynamixel servo or Zaber rotary stage)."""
    limits = TravelLimits(cfg.min_deg, cfg.max_deg)
    common = _StageKwargs(
        limits=limits,
        speed_dps=cfg.speed_dps,
        accel_dps2=cfg.accel_dps2,
        settle_s=cfg.settle_s,
        approach=cfg.approach,
        backlash_deg=cfg.backlash_deg,
        move_timeout_s=cfg.move_timeout_s,
    )
    if cfg.driver == "dynamixel":
        # Imported here so a rig without this stage does not need its SDK to import cleanly.
        from gonio.drivers.dynamixel import DynamixelStage

        dxl_id = cfg.dynamixel.id if cfg.dynamixel is not None else 1
        return DynamixelStage(
            STAGE_NAME,
            cfg.port,
            baudrate=cfg.default_baudrate,
            dxl_id=dxl_id,
            reply_timeout_s=cfg.dynamixel.reply_timeout_s if cfg.dynamixel is not None else None,
            counts_per_degree=cfg.counts_per_degree,
            **common,
        )
    from gonio.drivers.zaber import ZaberStage

    device, axis = (cfg.zaber.device, cfg.zaber.axis) if cfg.zaber is not None else (1, 1)
    return ZaberStage(
        STAGE_NAME,
        cfg.port,
        baudrate=cfg.default_baudrate,
        device=device,
        axis=axis,
        microsteps_per_degree=cfg.microsteps_per_stage_degree,
        **common,
    )


def build_rig(config: RigConfig) -> Rig:
    """A rig of real drivers for ``config``; lights and sensors on one gateway share a socket.

    Parameters
    ----------
    config : RigConfig
        From :func:`gonio.config.load_rig_config`.

    Returns
    -------
    Rig
        Not yet connected.
    """
    pool = ModbusPool()
    lights: dict[str, Light] = {x.name: ModbusLight(x, pool) for x in config.lights}
    sensors: dict[str, Sensor] = {x.name: ModbusSensor(x, pool) for x in config.sensors}
    return Rig(build_stage(config.stage), lights, sensors, config.pair_list())
