"""Placement during a search: keeping every design the search visits mountable.

:class:`MountPlanner` places pairs one at a time as the search
(:func:`gonio.brdf.design.search.optimize_rows`) moves them; :class:`Mounting` is the placement
the search currently holds.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from gonio.brdf.design.constraints import (
    RigConstraints,
    device_ok,
    on_axis_ph,
    ph_options,
    rows_to_cells,
)
from gonio.brdf.tables import geometry as geo

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]


@dataclass
class Mounting:
    """Lab placement of the pairs a search currently holds (mutable search state).

    Attributes
    ----------
    rows : (n,) int array
        Flat grid row (cell) of each pair.
    az : (n,) int array
        Index into :attr:`MountPlanner.ph` of each pair's lab half-vector azimuth.
    devices : (n, 2, 3) array
        Light and sensor direction of each pair at that azimuth (lab, unit vectors).
    """

    rows: NDArray[np.intp]
    az: NDArray[np.intp]
    devices: FloatArray

    def copy(self) -> Mounting:
        return Mounting(self.rows.copy(), self.az.copy(), self.devices.copy())


class MountPlanner:
    """Incremental, collision-free placement of pairs for a search over grid cells.

    A pair's lab azimuth ``ph`` is free (it does not change ``kappa``), so a cell can join a
    design when some azimuth keeps both its devices out of every exclusion and at least
    ``min_device_distance_deg`` from every device already mounted. Rotating ``ph`` rotates both
    devices about the lab normal, so every azimuth of a cell comes from one pair of directions
    and a table of sines and cosines. Among the azimuths that fit, the one whose closest device
    is farthest away is taken (maximin), leaving room for later moves.

    Parameters
    ----------
    constraints : RigConstraints
    ph_step_deg : float
        Azimuth resolution, degrees (the same grid :func:`place_pairs` uses by default).
    nudges : int
        Azimuths tried when a move fits only if one neighbouring pair is re-placed (0: never
        re-place a neighbour).

    Rows are flat indices of the standard ``(th, td, pd)`` grid (:func:`rows_to_cells`).
    """

    def __init__(
        self, constraints: RigConstraints, ph_step_deg: float = 1.0, nudges: int = 4
    ) -> None:
        self.constraints = constraints
        self._nudges = int(nudges)
        self.ph = ph_options(ph_step_deg)
        self._cos_ph = np.cos(self.ph)
        self._sin_ph = np.sin(self.ph)
        # dot(Rz(ph) v, u) = cos ph (v_x u_x + v_y u_y) + sin ph (v_x u_y - v_y u_x) + v_z u_z,
        # so the cosines between a turned device and fixed ones, at every azimuth, are one
        # (P, 3) x (3, D) product with this table; nothing needs turning.
        self._trig = np.stack([self._cos_ph, self._sin_ph, np.ones_like(self.ph)], axis=1)
        # Two devices collide when their angle is below the limit, i.e. their cosine above
        # cos(limit); the slack matches place_pairs' 1e-9 rad tolerance.
        need = math.radians(constraints.min_device_distance_deg)
        self._cos_need = math.cos(max(need - 1e-9, 0.0)) if need > 0.0 else math.inf
        # Per row: its devices at ph = 0 and where both are allowed (a search revisits rows).
        self._cache: dict[int, tuple[FloatArray, BoolArray]] = {}

    @property
    def collisions_possible(self) -> bool:
        """Whether mounted pairs can get in each other's way (a device-distance limit is set).

        Without one, any feasible cell fits at any of its allowed azimuths whatever else is
        mounted, so a search need not track placements.
        """
        return self.constraints.min_device_distance_deg > 0.0

    def _rotated(self, v: FloatArray) -> FloatArray:
        """(P, 3): ``v`` rotated about the lab normal by every azimuth of :attr:`ph`."""
        x = self._cos_ph * v[0] - self._sin_ph * v[1]
        y = self._sin_ph * v[0] + self._cos_ph * v[1]
        return np.stack([x, y, np.full_like(x, v[2])], axis=-1)

    def _row(self, row: int) -> tuple[FloatArray, BoolArray]:
        """(2, 3) devices of ``row`` at ``ph = 0`` and its (P,) allowed azimuths, cached."""
        got = self._cache.get(row)
        if got is None:
            th, td, pd = rows_to_cells(np.array([row]))[0]
            wi0, wo0 = geo.half_diff_to_directions(th, 0.0, td, pd)
            wi, wo = self._rotated(wi0), self._rotated(wo0)
            allowed = device_ok(wi, self.constraints) & device_ok(wo, self.constraints)
            allowed &= on_axis_ph(np.array([[th, td, pd]]), self.ph)[0]
            got = (np.stack([wi0, wo0]), allowed)
            self._cache[row] = got
        return got

    def azimuth_options(self, row: int) -> tuple[FloatArray, FloatArray, BoolArray]:
        """Devices of flat grid ``row`` at every azimuth, and where both are allowed.

        Returns
        -------
        wi, wo : (P, 3) arrays
            Light and sensor directions at each azimuth of :attr:`ph`.
        allowed : (P,) bool
            Both devices within the elevation limit and outside every exclusion (and only
            ``ph = 0`` for a ``th = 0`` cell, see :func:`on_axis_ph`).
        """
        dev0, allowed = self._row(row)
        return self._rotated(dev0[0]), self._rotated(dev0[1]), allowed

    def _cosines(self, dev0: FloatArray, others: FloatArray) -> FloatArray:
        """(P, 2, D): cosine between each device of a pair turned to every azimuth and others.

        ``dev0`` (2, 3) are the pair's devices at ``ph = 0``; ``others`` (D, 3).
        """
        v, u = dev0[:, None, :], others[None, :, :]
        m = np.stack([
            v[..., 0] * u[..., 0] + v[..., 1] * u[..., 1],
            v[..., 0] * u[..., 1] - v[..., 1] * u[..., 0],
            v[..., 2] * u[..., 2],
        ])  # (3, 2, D)
        return (self._trig @ m.reshape(3, -1)).reshape(self.ph.size, 2, -1)

    def _turned(self, dev0: FloatArray, j: int) -> FloatArray:
        """(2, 3): the pair's devices at azimuth index ``j``."""
        c, s = self._cos_ph[j], self._sin_ph[j]
        x, y = dev0[:, 0], dev0[:, 1]
        return np.stack([c * x - s * y, s * x + c * y, dev0[:, 2]], axis=1)

    def best_azimuth(self, row: int, others: ArrayLike) -> tuple[int, FloatArray]:
        """Maximin azimuth for ``row`` among the devices ``others`` (D, 3).

        Returns
        -------
        index : int
            Index into :attr:`ph`, or -1 when no allowed azimuth keeps both devices far enough
            from every device in ``others``.
        devices : (2, 3) array
            Light and sensor direction at that azimuth (meaningless when ``index`` is -1).
        """
        dev0, allowed = self._row(row)
        dev = np.asarray(others, dtype=float).reshape(-1, 3)
        if dev.shape[0]:
            # Largest cosine = closest device.
            closest = self._cosines(dev0, dev).reshape(self.ph.size, -1).max(axis=1)
        else:
            closest = np.full(self.ph.size, -1.0)
        fits = allowed & (closest <= self._cos_need)
        if not fits.any():
            return -1, np.zeros((2, 3))
        j = int(np.argmin(np.where(fits, closest, np.inf)))
        return j, self._turned(dev0, j)

    def start(
        self, rng: np.random.Generator, candidates: ArrayLike, n: int
    ) -> tuple[NDArray[np.intp], Mounting] | None:
        """A random collision-free design: ``n`` candidate rows added in random order.

        Rows that do not fit beside those already mounted are skipped; None when the
        candidates run out before ``n`` fit.

        Returns
        -------
        rows : (n,) int array
        mounting : Mounting
        """
        rows: list[int] = []
        az: list[int] = []
        devices: list[FloatArray] = []
        for r in rng.permutation(np.asarray(candidates, dtype=np.intp)):
            placed = np.concatenate(devices) if devices else np.zeros((0, 3))
            j, dev = self.best_azimuth(int(r), placed)
            if j < 0:
                continue
            rows.append(int(r))
            az.append(j)
            devices.append(dev)
            if len(rows) == n:
                picked = np.array(rows, dtype=np.intp)
                return picked, Mounting(picked.copy(), np.array(az, dtype=np.intp),
                                        np.stack(devices))
        return None

    def move(self, mounting: Mounting, slot: int, row: int) -> bool:
        """Mount ``row`` in place of pair ``slot``; False if it cannot be made to fit.

        First with every other pair held. Failing that, a neighbour may step aside: at the
        azimuths where the new devices are too close to exactly one other pair, that pair is
        re-placed (maximin) around the rest, trying the most open such azimuths first. Only
        one pair other than ``slot`` ever moves, and its cell stays the same, so ``kappa``
        does not change. ``mounting`` is updated only on success.
        """
        keep = np.arange(mounting.az.size) != slot
        others = mounting.devices[keep]  # (n - 1, 2, 3)
        dev0, allowed = self._row(row)
        # Closest approach (largest cosine) of the new pair to each other pair, per azimuth;
        # elementwise maxima over strided views are much cheaper than a multi-axis reduce.
        cos = self._cosines(dev0, others.reshape(-1, 3))  # (P, 2, 2 (n - 1))
        either = np.maximum(cos[:, 0], cos[:, 1])
        per_pair = np.maximum(either[:, 0::2], either[:, 1::2])  # (P, n - 1)
        closest = per_pair.max(axis=1) if per_pair.shape[1] else np.full(self.ph.size, -1.0)
        fits = allowed & (closest <= self._cos_need)
        if fits.any():
            j = int(np.argmin(np.where(fits, closest, np.inf)))
            self._set(mounting, slot, row, j, self._turned(dev0, j))
            return True
        if others.shape[0] < 2 or self._nudges == 0:
            return False
        blocking = per_pair > self._cos_need
        one = allowed & (blocking.sum(axis=1) == 1)
        if not one.any():
            return False
        rest_closest = np.where(blocking, -np.inf, per_pair).max(axis=1)
        tries = np.flatnonzero(one)
        tries = tries[np.argsort(rest_closest[tries], kind="stable")][: self._nudges]
        pair_ids = np.flatnonzero(keep)
        for jj in tries:
            p = int(np.argmax(blocking[jj]))  # the one pair in the way, among the others
            new_dev = self._turned(dev0, int(jj))
            rest = np.delete(others, p, axis=0).reshape(-1, 3)
            target = int(pair_ids[p])
            jp, dev_p = self.best_azimuth(int(mounting.rows[target]),
                                          np.concatenate([rest, new_dev]))
            if jp >= 0:
                self._set(mounting, slot, row, int(jj), new_dev)
                self._set(mounting, target, int(mounting.rows[target]), jp, dev_p)
                return True
        return False

    @staticmethod
    def _set(mounting: Mounting, slot: int, row: int, az: int, dev: FloatArray) -> None:
        mounting.rows[slot] = row
        mounting.az[slot] = az
        mounting.devices[slot] = dev
