"""A rig of real drivers from a rig config: which driver serves which section, with the
config's numbers converted as its documentation says; nothing is opened. The drivers
against their simulators: tests/system/drivers/."""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Any

import pytest

from gonio.config import parse_rig_config
from gonio.drivers.dynamixel import DynamixelStage
from gonio.drivers.factory import STAGE_NAME, build_rig, build_stage
from gonio.drivers.modbus import ModbusLight, ModbusSensor
from gonio.drivers.zaber import ZaberStage
from gonio.hal import TravelLimits

EXAMPLE = Path(__file__).resolve().parents[3] / "deploy" / "rig.example.toml"


def example() -> dict[str, Any]:
    with EXAMPLE.open("rb") as f:
        return tomllib.load(f)


def test_the_example_rig_gets_a_dynamixel_stage_and_modbus_devices() -> None:
    rig = build_rig(parse_rig_config(example()))
    stage = rig.stage
    assert isinstance(stage, DynamixelStage) and stage.name == STAGE_NAME
    # deploy/rig.example.toml: 4096 counts per motor turn, gear 3: 4096 * 3 / 360 per degree
    assert stage.cpd == pytest.approx(4096 * 3 / 360)
    assert (stage.baudrate, stage.dxl_id) == (57600, 1)
    assert stage.limits == TravelLimits(-5.0, 365.0)
    assert (stage.speed_dps, stage.accel_dps2, stage.settle_s) == (30.0, 60.0, 0.2)
    assert (stage.approach, stage.backlash_deg, stage.move_timeout_s) == ("positive", 0.5, 60.0)
    assert all(isinstance(x, ModbusLight) for x in rig.lights.values())
    assert all(isinstance(x, ModbusSensor) for x in rig.sensors.values())
    # pairs = "all": every light with every sensor
    assert len(rig.pairs) == len(rig.lights) * len(rig.sensors)
    # one pool per rig, so devices behind one gateway share its socket
    devices: list[Any] = [*rig.lights.values(), *rig.sensors.values()]
    pools = {id(d._io._pool) for d in devices}
    assert len(pools) == 1


def test_a_zaber_stage_with_the_vendor_defaults() -> None:
    data = example()
    stage_cfg = data["stage"]
    stage_cfg.update(driver="zaber", microsteps_per_degree=200.0, gear_ratio=2.0)
    for key in ("dynamixel", "baudrate", "counts_per_rev"):
        stage_cfg.pop(key, None)
    stage_cfg["zaber"] = {"device": 2, "axis": 1}
    stage = build_stage(parse_rig_config(data).stage)
    assert isinstance(stage, ZaberStage)
    # microsteps per stage degree = per motor degree x gear ratio; Zaber's default 115200 baud
    assert stage.mpd == pytest.approx(400.0) and stage.resolution_deg == pytest.approx(1 / 400)
    assert (stage.device, stage.axis, stage.baudrate) == (2, 1, 115200)


def test_a_dynamixel_stage_without_its_table_is_servo_id_1() -> None:
    data = example()
    del data["stage"]["dynamixel"]
    stage = build_stage(parse_rig_config(data).stage)
    assert isinstance(stage, DynamixelStage) and stage.dxl_id == 1
