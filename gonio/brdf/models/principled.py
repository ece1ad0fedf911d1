"""Principled (Disney-style) parameters fitted to a tabulated BRDF (004 App. A.3, math.md 11-12).

The parameters renderers take: base colour, metallic, specular, roughness, anisotropy strength
and direction. They describe, as in :func:`gonio.brdf.models.analytic.principled` and 004 App. A.3,

* a Lambert term ``(1 - metallic) (1 - F_d(wi.h)) base / pi``, weighted by what the
  dielectric specular layer leaves: glTF 2.0's ``fresnel_mix`` (Appendix B and
  ``KHR_materials_specular``), which the exports are;
* an anisotropic GGX lobe with separable Smith masking and the Fresnel factor
  ``(1 - metallic) F_d(wi.h) + metallic S(base, wi.h)`` per channel, ``S(F0, c) = F0 + (1 -
  F0)(1 - c)^5`` Schlick's, with the dielectric's ``F_d = specular_weight S(0.08 specular, c)``:
  normal-incidence reflectance ``specular_weight 0.08 specular``, grazing ``specular_weight``
  (``specular = 0.5``, weight 1 give the dielectric ``F0 = 0.04`` of 004 Eq. 9; Burley 2012
  scales it so). With weight 1 this is Schlick's Fresnel of ``F0 = mix(0.08 specular, base,
  metallic)``. ``specular`` runs from 0 to :data:`SPECULAR_LEVEL_MAX` = 12.5: above Burley's 1
  (``F0`` 0.08) the same linear map goes on to ``F0 = 1``. In glTF's
  ``KHR_materials_specular`` the weight is ``specularFactor`` and ``specular`` is
  ``specularColorFactor / 2`` (a diffuse colour under a bright highlight, a coated or dusty
  metal, is a high level, possibly with a weight below 1; issue 26);
* optionally (``f82_tint``, OpenPBR's metal, issue 26) the metal's Fresnel factor is the
  F82-tint one of the OpenPBR specification (after Hoffman 2019 and Kutz et al. 2021),
  :class:`F82TintFresnel`: Schlick's curve less ``b mu (1 - mu)^6``, with ``b`` chosen so
  that at ``mu_bar = 1/7`` (about 82 degrees) the reflectance is ``tint x Schlick(mu_bar)``;
  a tint below 1 makes the reflectance dip before grazing, as aluminium's does. glTF has
  no such term: only the MaterialX ``open_pbr_surface`` export carries it;
* roughnesses ``alpha_t`` along the tangent and ``alpha_b`` across it, with the tangent at
  azimuth ``direction`` in the specimen frame (from the holder mark, counter-clockwise).

Roughness and anisotropy follow Burley 2012: ``alpha_t = r^2 / aspect``,
``alpha_b = r^2 aspect``, ``aspect = sqrt(1 - 0.9 anisotropy)``; so ``r^2 = sqrt(alpha_t
alpha_b)`` and the tangent is the *rougher* axis (the highlight stretches along it). The
direction is defined modulo 180 degrees and reported in ``[0, 180)``. Each export format maps
``(alpha_t, alpha_b, direction)`` to its own convention (:mod:`gonio.export`).

Fit: nonlinear least squares (``scipy.optimize.least_squares``) of all parameters at once on a
fixed random subset of the table's valid cells, residuals the cosine-weighted log error of
:func:`gonio.brdf.tables.metrics.log_rmse` times ``sqrt(wV)``, started from a GGX fit to the table's
``td = 0`` slice (there ``i = o = h``, so that slice is the NDF up to ``G^2 / cos^2``).
The reported error compares the fitted model's full table with the input table.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from gonio.brdf.models import analytic as bm
from gonio.brdf.models.factored import fit_metrics
from gonio.brdf.tables import geometry as geo
from gonio.brdf.tables.table import VALID_MASK, BRDFTable

FloatArray = NDArray[np.float64]
#: Burley's aspect ratio bound: anisotropy 1 means alpha_t / alpha_b = 10.
MAX_RATIO = 10.0
ALPHA_MIN, ALPHA_MAX = 1e-3, 2.0
#: Largest ``specular``: ``F0 = 0.08 specular`` reaches 1.
SPECULAR_LEVEL_MAX = 12.5


#: OpenPBR's F82-tint reference cosine ``mu_bar = 1/7`` (an angle of about 81.8 degrees).
MU_BAR = 1.0 / 7.0


class PrincipledError(ValueError):
    """Principled parameters out of range, or a table that cannot be fitted."""


def schlick(f0: float | FloatArray, cos_d: FloatArray) -> FloatArray:
    """Schlick's Fresnel ``F0 + (1 - F0)(1 - cos)^5`` of (N,) cosines (clipped to [0, 1])."""
    c = np.clip(cos_d, 0.0, 1.0)
    return np.asarray(f0 + (1.0 - np.asarray(f0)) * (1.0 - c) ** 5, dtype=float)


def f82_tint_fresnel(f0: Any, tint: Any, cos_d: FloatArray) -> FloatArray:
    """OpenPBR's F82-tint metal Fresnel of (N,) cosines -> (N, C), clipped to [0, 1].

    ``F(mu) = S(mu) - b mu (1 - mu)^6`` with Schlick's ``S(mu) = F0 + (1 - F0)(1 - mu)^5``
    and ``b = S(mu_bar)(1 - tint) / (mu_bar (1 - mu_bar)^6)``, ``mu_bar = 1/7``, so that
    ``F(mu_bar) = tint S(mu_bar)`` (OpenPBR specification, "Metal"). With ``tint = 1`` it
    is Schlick's. The correction can take the curve below 0 between ``mu_bar`` and 1 for a
    dark ``F0`` and a small tint; reflectance cannot be negative, so it is clipped.

    Parameters
    ----------
    f0, tint : (C,) floats in [0, 1]
    cos_d : (N,) cosines between the light and the microfacet normal
    """
    f0a = np.asarray(f0, dtype=float)[None, :]
    ta = np.asarray(tint, dtype=float)[None, :]
    c = np.clip(np.asarray(cos_d, dtype=float), 0.0, 1.0)[:, None]
    s_bar = f0a + (1.0 - f0a) * (1.0 - MU_BAR) ** 5
    b = s_bar * (1.0 - ta) / (MU_BAR * (1.0 - MU_BAR) ** 6)
    f = f0a + (1.0 - f0a) * (1.0 - c) ** 5 - b * c * (1.0 - c) ** 6
    return np.asarray(np.clip(f, 0.0, 1.0), dtype=float)


@dataclass(frozen=True)
class F82TintFresnel(bm.SchlickFresnel):
    """Schlick's Fresnel with OpenPBR's F82 tint (:func:`f82_tint_fresnel`), per channel.

    A :class:`gonio.brdf.models.analytic.SchlickFresnel` (``f0``) with a ``tint``: the
    analytic GGX takes it where it takes Schlick's.
    """

    tint: tuple[float, ...] = (1.0,)

    def __post_init__(self) -> None:
        super().__post_init__()
        tint = tuple(float(v) for v in np.atleast_1d(self.tint))
        if any(not 0.0 <= v <= 1.0 for v in tint):
            raise PrincipledError(f"F82 tint {tint} is outside [0, 1]")
        object.__setattr__(self, "tint", tint)

    def reflectance(self, cos_d: FloatArray, n_channels: int) -> FloatArray:
        """(N,) cosine between light and microfacet normal -> (N, C) reflectance in [0, 1]."""
        f0 = np.broadcast_to(np.asarray(self.f0, dtype=float), (n_channels,))
        tint = np.broadcast_to(np.asarray(self.tint, dtype=float), (n_channels,))
        return f82_tint_fresnel(f0, tint, cos_d)


@dataclass(frozen=True)
class LayeredDiffuse:
    """Lambert under a dielectric specular layer: ``(1 - weight S(f0, wi.h)) albedo / pi``.

    ``S`` is Schlick's Fresnel of the grey ``f0``: the diffuse gets what the specular layer
    does not reflect, as glTF 2.0's ``fresnel_mix`` weighs it (``base`` with ``1 - weight
    max_value(fr)``, ``KHR_materials_specular``).

    Parameters
    ----------
    albedo : (C,) floats in [0, 1]
    f0 : float in [0, 1]
    weight : float in [0, 1]
    """

    albedo: tuple[float, ...]
    f0: float
    weight: float = 1.0
    channels: tuple[str, ...] = bm.RGB
    name: str = "layered-diffuse"
    isotropic: bool = True

    def eval(self, wi: Any, wo: Any) -> FloatArray:
        """(..., 3) + (..., 3) unit vectors -> (..., C) in 1/sr; 0 below the horizon."""
        i, o = np.broadcast_arrays(np.asarray(wi, dtype=float), np.asarray(wo, dtype=float))
        lam = bm.Lambert(self.albedo, channels=self.channels).eval(i, o)
        h = i + o
        h = h / np.maximum(np.linalg.norm(h, axis=-1, keepdims=True), 1e-300)
        keep = 1.0 - self.weight * schlick(self.f0, np.sum(i * h, axis=-1))
        return np.asarray(lam * keep[..., None], dtype=float)


@dataclass(frozen=True)
class Principled:
    """Principled BRDF parameters (module docstring for their meaning).

    Parameters
    ----------
    base_color : (C,) floats in [0, 1]
    metallic : float in [0, 1]
    specular : float in [0, 12.5]
        Dielectric ``F0 = 0.08 specular`` before the weight (Burley's range is [0, 1]; above
        it, module docstring).
    alpha_t, alpha_b : float in [1e-3, 2], ``alpha_t >= alpha_b``
        GGX roughness along and across the tangent.
    direction_deg : float in [0, 180)
        Azimuth of the tangent (the rougher axis) in the specimen frame, degrees.
    channels : tuple of str
    metrics : mapping
        Fit error against the fitted table and fit timing.
    specular_weight : float in [0, 1]
        Weight of the dielectric's specular layer (its reflectance at grazing angles; module
        docstring); 1 is Burley's model.
    f82_tint : (C,) floats in [0, 1] or None
        The metal's OpenPBR F82 tint (module docstring); None (glTF's model) is Schlick's,
        as is a tint of 1.
    """

    base_color: tuple[float, ...]
    metallic: float
    specular: float
    alpha_t: float
    alpha_b: float
    direction_deg: float
    channels: tuple[str, ...] = bm.RGB
    metrics: Mapping[str, Any] = field(default_factory=dict)
    specular_weight: float = 1.0
    f82_tint: tuple[float, ...] | None = None

    def __post_init__(self) -> None:
        base = tuple(float(b) for b in self.base_color)
        if len(base) != len(self.channels):
            raise PrincipledError(
                f"{len(base)} base colour values for {len(self.channels)} channels"
            )
        for what, vals, lo, hi in (
            ("base_color", base, 0.0, 1.0), ("metallic", (self.metallic,), 0.0, 1.0),
            ("specular", (self.specular,), 0.0, SPECULAR_LEVEL_MAX),
            ("specular_weight", (self.specular_weight,), 0.0, 1.0),
            ("alpha_t", (self.alpha_t,), ALPHA_MIN, ALPHA_MAX),
            ("alpha_b", (self.alpha_b,), ALPHA_MIN, ALPHA_MAX),
        ):
            for v in vals:
                if not lo <= v <= hi:
                    raise PrincipledError(f"{what} = {v} is outside [{lo}, {hi}]")
        if self.alpha_b > self.alpha_t:
            raise PrincipledError(
                f"alpha_b = {self.alpha_b} > alpha_t = {self.alpha_t}: the tangent is the "
                "rougher axis; swap them and turn the direction by 90 degrees"
            )
        if self.f82_tint is not None:
            tint = tuple(float(t) for t in self.f82_tint)
            if len(tint) != len(self.channels) or any(not 0.0 <= t <= 1.0 for t in tint):
                raise PrincipledError(
                    f"f82_tint {tint} must be {len(self.channels)} values in [0, 1]")
            object.__setattr__(self, "f82_tint", tint)
        object.__setattr__(self, "base_color", base)
        object.__setattr__(self, "direction_deg", float(self.direction_deg) % 180.0)
        object.__setattr__(self, "metrics", dict(self.metrics))

    @property
    def roughness(self) -> float:
        """Burley roughness ``r = (alpha_t alpha_b)^(1/4)``."""
        return float((self.alpha_t * self.alpha_b) ** 0.25)

    @property
    def anisotropy(self) -> float:
        """Burley anisotropy in [0, 1]: ``(1 - alpha_b / alpha_t) / 0.9``, capped at 1."""
        return float(min(1.0, (1.0 - self.alpha_b / self.alpha_t) / 0.9))

    @property
    def dielectric_f0(self) -> float:
        """The dielectric part's normal-incidence reflectance ``specular_weight 0.08
        specular`` (grey)."""
        return self.specular_weight * min(1.0, 0.08 * self.specular)

    @property
    def f0(self) -> tuple[float, ...]:
        """Normal-incidence specular reflectance per channel."""
        s = self.dielectric_f0
        return tuple(s + (b - s) * self.metallic for b in self.base_color)

    def model(self, name: str = "principled") -> bm.LobeSum:
        """The analytic model these parameters describe."""
        def lobe(f0: tuple[float, ...], what: str,
                 tint: tuple[float, ...] | None = None) -> bm.Rotated:
            fresnel = bm.SchlickFresnel(f0) if tint is None else F82TintFresnel(f0, tint)
            spec = bm.GGX(self.alpha_t, self.alpha_b, fresnel, "separable",
                          channels=self.channels, name=f"{name}/{what}")
            return bm.Rotated(spec, math.radians(self.direction_deg))

        level = min(1.0, 0.08 * self.specular)
        diffuse = LayeredDiffuse(tuple((1.0 - self.metallic) * b for b in self.base_color),
                                 level, self.specular_weight, channels=self.channels,
                                 name=f"{name}/diffuse")
        lobes: list[Any] = [diffuse]
        weights: list[float] = [1.0]
        if self.f82_tint is not None and self.metallic > 0.0:
            # The tint bends the metal's curve only: its lobe apart from the dielectric's
            if self.metallic < 1.0:
                lobes.append(lobe((level,) * len(self.channels), "dielectric"))
                weights.append((1.0 - self.metallic) * self.specular_weight)
            lobes.append(lobe(self.base_color, "metal", self.f82_tint))
            weights.append(self.metallic)
        elif self.specular_weight == 1.0 or self.metallic == 1.0:
            # Schlick's Fresnel is linear in F0: one lobe of F0 = mix(level, base, metallic)
            lobes.append(lobe(self.f0, "spec"))
            weights.append(1.0)
        else:
            lobes.append(lobe((level,) * len(self.channels), "dielectric"))
            weights.append((1.0 - self.metallic) * self.specular_weight)
            if self.metallic > 0.0:
                lobes.append(lobe(self.base_color, "metal"))
                weights.append(self.metallic)
        return bm.LobeSum(tuple(lobes), weights, channels=self.channels, name=name)

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready parameters, derived renderer values included (angles in degrees)."""
        return {
            "base_color": list(self.base_color), "metallic": self.metallic,
            "specular": self.specular, "specular_weight": self.specular_weight,
            "roughness": self.roughness,
            "anisotropy": self.anisotropy, "direction_deg": self.direction_deg,
            "alpha_t": self.alpha_t, "alpha_b": self.alpha_b, "f0": list(self.f0),
            "channels": list(self.channels), "metrics": dict(self.metrics),
            **({} if self.f82_tint is None else {"f82_tint": list(self.f82_tint)}),
        }

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> Principled:
        """Inverse of :meth:`as_dict` (derived values are recomputed, not read)."""
        try:
            return cls(
                tuple(d["base_color"]), float(d["metallic"]), float(d["specular"]),
                float(d["alpha_t"]), float(d["alpha_b"]), float(d["direction_deg"]),
                tuple(d.get("channels", bm.RGB)), d.get("metrics", {}),
                float(d.get("specular_weight", 1.0)),  # 1 before issue 26's weight
                None if d.get("f82_tint") is None else tuple(d["f82_tint"]),
            )
        except (KeyError, TypeError) as exc:
            raise PrincipledError(f"malformed principled parameters ({exc})") from None


# ---------------------------------------------------------------------------- fitting
def _lobe_init(table: BRDFTable) -> tuple[float, float, float]:
    """``(alpha_x, alpha_y, angle)`` of a GGX NDF fitted to the table's ``td = 0`` slice.

    At ``td = 0`` light and view coincide with the half vector, so
    ``f - diffuse = D(h) F(0) G1(h)^2 / (4 cos^2 th)``; near the normal ``G1 ~ 1`` and
    ``f cos^2 th`` follows the NDF. Fitted in the log domain over ``th <= 60`` deg, from four
    starting directions.
    """
    from scipy.optimize import least_squares

    t0 = np.nanmean(np.asarray(table.values, dtype=float)[:, :, :, 0, 0], axis=0)  # (72, 18)
    lobe = t0 - np.nanmin(t0)
    th, ph = np.meshgrid(geo.TH_GRID, geo.PH_GRID, indexing="xy")  # (72, 18)
    keep = (th <= np.deg2rad(60)) & np.isfinite(lobe) & (lobe > 1e-3 * np.nanmax(lobe))
    if keep.sum() < 8:
        return 0.5, 0.5, 0.0  # no visible lobe: a rough, isotropic start
    target = np.log(lobe[keep] * np.cos(th[keep]) ** 2)
    h = geo.spherical_to_direction(th[keep], ph[keep])

    def resid(p: FloatArray) -> FloatArray:
        ax, ay = np.exp(p[1]), np.exp(p[2])
        d = bm.ggx_ndf(geo.rotate_z(h, -p[3]), ax, ay)
        return np.asarray(p[0] + np.log(d) - target, dtype=float)

    best: Any = None
    for start in (0.0, 0.25 * np.pi, 0.5 * np.pi, 0.75 * np.pi):
        p0 = np.array([0.0, math.log(0.2), math.log(0.3), start])
        p0[0] = float(np.mean(target - (resid(p0) - p0[0] + target)))
        r = least_squares(resid, p0, bounds=(
            [-np.inf, math.log(ALPHA_MIN), math.log(ALPHA_MIN), -np.inf],
            [np.inf, math.log(ALPHA_MAX), math.log(ALPHA_MAX), np.inf]))
        if best is None or r.cost < best.cost:
            best = r
    return float(np.exp(best.x[1])), float(np.exp(best.x[2])), float(best.x[3])


def _sample_cells(n: int, seed: int) -> tuple[FloatArray, FloatArray, NDArray[np.intp],
                                                 NDArray[np.intp], FloatArray]:
    """A fixed random subset of (ph slice, valid cell): directions, indices, weights."""
    rng = np.random.default_rng(seed)
    th, td, pd = geo.grid_angles()
    nv = int(VALID_MASK.sum())
    flat = rng.choice(geo.N_PH * nv, size=min(n, geo.N_PH * nv), replace=False)
    k, v = np.divmod(flat, nv)
    wi, wo = geo.half_diff_to_directions(
        th[VALID_MASK][v], geo.PH_GRID[k], td[VALID_MASK][v], pd[VALID_MASK][v])
    return wi, wo, k.astype(np.intp), v.astype(np.intp), geo.volume_weight()[VALID_MASK][v]


def fit_principled(table: BRDFTable, *, n_cells: int = 12000, seed: int = 0) -> Principled:
    """Fit principled parameters to a table (module docstring for the method).

    Parameters
    ----------
    table : BRDFTable, 1/sr
    n_cells : int
        Size of the random subset of (slice, cell) pairs the residuals use.
    seed : int
        Seed of that subset (the fit is deterministic for a given seed).

    Returns
    -------
    Principled
        With ``metrics``: ``rel_mse``, ``mape``, ``psnr``, ``log_rmse`` of the principled
        model's table against ``table``, ``cost`` (final mean squared log residual) and
        ``seconds``.

    Raises
    ------
    PrincipledError
        The table has no positive finite value.
    """
    from scipy.optimize import least_squares

    t_start = time.perf_counter()
    vals = np.asarray(table.values, dtype=float)
    if not (np.isfinite(vals) & (vals > 0)).any():
        raise PrincipledError(f"table {table.name!r} has no positive finite value to fit")
    nc = table.n_channels
    wi, wo, k, v, wv = _sample_cells(n_cells, seed)
    y = vals[:, :, VALID_MASK][:, k, v].T  # (N, C)
    ok = np.isfinite(y)
    y = np.where(ok, y, 0.0)
    cos_i = wi[:, 2:3]
    target = np.log1p(y * cos_i)
    sw = np.sqrt(wv / wv.sum())[:, None] * ok

    ax, ay, ang = _lobe_init(table)
    diffuse0 = np.clip(np.pi * np.nanquantile(y, 0.05, axis=0), 0.0, 1.0)
    # p = [base (C), metallic, specular, log alpha_x, log alpha_y, angle]
    p0 = np.concatenate([np.maximum(diffuse0, 0.05), [0.5, 0.5, math.log(ax), math.log(ay), ang]])
    lo = np.concatenate([np.zeros(nc), [0.0, 0.0, math.log(ALPHA_MIN), math.log(ALPHA_MIN),
                                        -np.inf]])
    hi = np.concatenate([np.ones(nc), [1.0, 1.0, math.log(ALPHA_MAX), math.log(ALPHA_MAX),
                                       np.inf]])
    p0 = np.clip(p0, lo + 1e-9, np.where(np.isfinite(hi), hi - 1e-9, hi))

    def predict(p: FloatArray) -> FloatArray:
        base, m, s = p[:nc], p[nc], p[nc + 1]
        alpha_x, alpha_y, a = math.exp(p[nc + 2]), math.exp(p[nc + 3]), p[nc + 4]
        f0 = 0.08 * s * (1 - m) + base * m
        i = geo.rotate_z(wi, -a)
        o = geo.rotate_z(wo, -a)
        h = i + o
        h /= np.linalg.norm(h, axis=1, keepdims=True)
        d = bm.ggx_ndf(h, alpha_x, alpha_y)
        g = 1.0 / ((1.0 + bm.ggx_lambda(i, alpha_x, alpha_y))
                   * (1.0 + bm.ggx_lambda(o, alpha_x, alpha_y)))
        c = np.clip(np.sum(i * h, axis=1), 0.0, 1.0)[:, None]
        fres = f0[None, :] + (1.0 - f0[None, :]) * (1.0 - c) ** 5
        spec = (d * g / (4.0 * i[:, 2] * o[:, 2]))[:, None] * fres
        keep = 1.0 - schlick(0.08 * s, c)  # LayeredDiffuse
        return np.asarray((1 - m) * base[None, :] * keep / np.pi + spec, dtype=float)

    def resid(p: FloatArray) -> FloatArray:
        return np.asarray((sw * (np.log1p(predict(p) * cos_i) - target)).ravel(), dtype=float)

    r = least_squares(resid, p0, bounds=(lo, hi), x_scale="jac", max_nfev=400)
    p = r.x
    base, m, s = p[:nc], float(p[nc]), float(p[nc + 1])
    alpha_x, alpha_y = math.exp(p[nc + 2]), math.exp(p[nc + 3])
    direction = math.degrees(p[nc + 4])
    if alpha_y > alpha_x:  # the tangent is the rougher axis
        alpha_x, alpha_y, direction = alpha_y, alpha_x, direction + 90.0
    params = Principled(
        tuple(float(b) for b in np.clip(base, 0.0, 1.0)), float(np.clip(m, 0, 1)),
        float(np.clip(s, 0, 1)), float(np.clip(alpha_x, ALPHA_MIN, ALPHA_MAX)),
        float(np.clip(alpha_y, ALPHA_MIN, ALPHA_MAX)), direction, table.channels,
    )
    quality: dict[str, Any] = dict(fit_metrics(bm.tabulate(params.model(), np.float64), table))
    quality.update(cost=float(2 * r.cost / max(int(ok.sum()), 1)),
                   seconds=round(time.perf_counter() - t_start, 3))
    return Principled(
        params.base_color, params.metallic, params.specular, params.alpha_t, params.alpha_b,
        params.direction_deg, params.channels, quality,
    )


def fit_f82_tint(table: BRDFTable, p: Principled, *, n_cells: int = 12000,
                 seed: int = 0) -> tuple[float, ...]:
    """The metal's F82 tint per channel that best fits ``table``, ``p``'s other parameters
    held (``p`` a metal).

    Fitted on the table, not on renderings: the tint changes the Fresnel factor only where
    ``wi.h`` is well below 1, i.e. light and view far apart (at ``wi.h = 1/7`` they are 164
    degrees apart), which no view of :mod:`gonio.export.judge` has (its lights are at most 55
    degrees from the view, ``wi.h >= 0.89``, where the correction is at most 3.3e-5 of the
    dip at 82 degrees: ``0.887 (1 - 0.887)^6 / (mu_bar (1 - mu_bar)^6)``). The residuals
    are :func:`fit_principled`'s (cosine-weighted log error on a fixed random subset of
    valid cells), bounds [0, 1], start 1 (Schlick's curve).

    Returns
    -------
    (C,) floats in [0, 1]

    Raises
    ------
    PrincipledError
        ``p`` is not a metal.
    """
    from scipy.optimize import least_squares

    if p.metallic != 1.0:
        raise PrincipledError(f"an F82 tint is a metal's; metallic is {p.metallic}")
    vals = np.asarray(table.values, dtype=float)
    wi, wo, k, v, wv = _sample_cells(n_cells, seed)
    y = vals[:, :, VALID_MASK][:, k, v].T  # (N, C)
    ok = np.isfinite(y)
    target = np.log1p(np.where(ok, y, 0.0) * wi[:, 2:3])
    sw = np.sqrt(wv / wv.sum())[:, None] * ok
    # The lobe without its Fresnel factor, evaluated once: the tint only scales it per cell
    plain = Principled(p.base_color, 1.0, 0.5, p.alpha_t, p.alpha_b, p.direction_deg,
                       p.channels).model().eval(wi, wo)
    h = wi + wo
    c = np.sum(wi * h, axis=1) / np.linalg.norm(h, axis=1)  # wi.h, the Fresnel's cosine
    schlick_f = schlick(np.asarray(p.base_color)[None, :], c[:, None])
    lobe = plain / np.maximum(schlick_f, 1e-12)

    def resid(t: FloatArray) -> FloatArray:
        pred = lobe * f82_tint_fresnel(p.base_color, t, c)
        return np.asarray((sw * (np.log1p(pred * wi[:, 2:3]) - target)).ravel(), dtype=float)

    nc = len(p.base_color)
    r = least_squares(resid, np.full(nc, 1.0 - 1e-6), bounds=(np.zeros(nc), np.ones(nc)),
                      x_scale="jac")
    return tuple(float(t) for t in np.clip(r.x, 0.0, 1.0))
