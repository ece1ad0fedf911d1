"""The static facts of a rig that plans are checked and timed against (no hardware).

A :class:`RigDescription` is taken from a connected-or-not :class:`gonio.hal.Rig` by reading its
attributes (nothing is connected or moved). It travels as JSON: the daemon stores one with every
job as its rig snapshot, and ``GET /api/v1/rig`` returns it.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray
from pydantic import BaseModel, ConfigDict, Field

from gonio import hal
from gonio.hal import PairSpec
from gonio.motion import Approach


class SensorInfo(BaseModel):
    """What a plan needs to know about one sensor."""

    model_config = ConfigDict(frozen=True)

    name: str
    theta_deg: float
    phi_deg: float
    channels: tuple[str, ...]
    min_exposure_s: float = 1e-4
    max_exposure_s: float = 10.0


class LightInfo(BaseModel):
    model_config = ConfigDict(frozen=True)

    name: str
    theta_deg: float
    phi_deg: float


class RigDescription(BaseModel):
    """The static facts about a rig that plans are checked and timed against (no hardware).

    Built from a :class:`gonio.hal.Rig` with :meth:`from_rig` (attributes only: nothing is
    connected or moved). Stored with each job as its rig snapshot.
    """

    model_config = ConfigDict(frozen=True)

    stage_min_deg: float
    stage_max_deg: float
    speed_dps: float = Field(gt=0)
    accel_dps2: float = Field(gt=0)
    settle_s: float = Field(default=0.0, ge=0)
    resolution_deg: float = Field(default=0.01, gt=0)
    approach: Approach = Field(
        default="none", description="side the stage driver approaches every target from")
    approach_backlash_deg: float = Field(
        default=0.0, ge=0, description="the driver's overshoot when a move arrives from the "
        "other side, degrees")
    lights: tuple[LightInfo, ...]
    sensors: tuple[SensorInfo, ...]
    pairs: tuple[PairSpec, ...]

    @classmethod
    def from_rig(cls, rig: hal.Rig) -> RigDescription:
        s = rig.stage
        return cls(
            stage_min_deg=s.limits.min_deg,
            stage_max_deg=s.limits.max_deg,
            speed_dps=s.speed_dps,
            accel_dps2=s.accel_dps2,
            settle_s=s.settle_s,
            resolution_deg=s.resolution_deg,
            approach=getattr(s, "approach", "none"),
            approach_backlash_deg=float(getattr(s, "backlash_deg", 0.0)),
            lights=tuple(
                LightInfo(name=n, theta_deg=lt.direction.theta_deg, phi_deg=lt.direction.phi_deg)
                for n, lt in rig.lights.items()
            ),
            sensors=tuple(
                SensorInfo(
                    name=n,
                    theta_deg=se.direction.theta_deg,
                    phi_deg=se.direction.phi_deg,
                    channels=tuple(se.channels),
                    min_exposure_s=se.min_exposure_s,
                    max_exposure_s=se.max_exposure_s,
                )
                for n, se in rig.sensors.items()
            ),
            pairs=tuple(rig.pairs),
        )

    def sensor(self, name: str) -> SensorInfo:
        """The sensor called ``name``; ``KeyError`` when there is none."""
        for s in self.sensors:
            if s.name == name:
                return s
        raise KeyError(name)

    def light(self, name: str) -> LightInfo:
        """The light called ``name``; ``KeyError`` when there is none."""
        for lt in self.lights:
            if lt.name == name:
                return lt
        raise KeyError(name)

    def pair_directions(
        self, pairs: Sequence[PairSpec]
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Lab unit vectors toward each pair's light and sensor at stage angle 0.

        Returns
        -------
        light_dirs, sensor_dirs : (n, 3) float64, in the order of ``pairs``
        """
        def vec(info: LightInfo | SensorInfo) -> tuple[float, float, float]:
            return hal.LabDirection(info.theta_deg, info.phi_deg).vector()

        return (np.asarray([vec(self.light(p.light)) for p in pairs], dtype=float),
                np.asarray([vec(self.sensor(p.sensor)) for p in pairs], dtype=float))
