"""The smallest roughness a sampling plan can resolve (math.md 11, Wiersma et al. 2025 App. C).

Sampling theory on the sphere: ``N`` well-spread samples recover spherical-harmonic degrees
``l* < sqrt(N)`` (a least-squares fit of degrees up to ``l*`` has ``(l* + 1)^2`` unknowns and
needs at least that many samples). A microfacet lobe of roughness ``alpha`` attenuates degree
``l`` by ``exp(-(alpha l)^2)``, so lobes with ``alpha`` below

    alpha' = sqrt(-ln t) / l*          (004 Eq. 12, t = 0.5)

still carry more than a fraction ``t`` of their energy above the resolvable band and cannot be
told apart from a sharper lobe.

Counting effective samples near the specular lobe
-------------------------------------------------
A pair at cell ``(th, td, pd)`` and lab azimuth ``ph_q``, read at stage angle ``alpha``, samples
the half vector ``(th, ph_q - alpha)``. The specular lobe lives around the normal in half-vector
space, so the samples that can resolve it are the distinct half vectors within ``cap_deg`` of
the normal (pairs at ``th = 0`` give the same half vector at every angle and count once).
Their density inside the cap is what limits the band: :func:`effective_samples` scales the
count to the whole sphere, ``N = N_cap * 4 pi / Omega_cap``, i.e. the number of samples a
uniform spherical design with the same spacing would have. ``l*`` is then the largest integer
with ``(l* + 1)^2 <= N`` (so ``l* < sqrt(N)`` holds).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from gonio.brdf.reconstruction.samples import uniform_stage_angles
from gonio.brdf.tables import geometry as geo

DEFAULT_ATTENUATION = 0.5
DEFAULT_CAP_DEG = 30.0


class RoughnessError(ValueError):
    """Bad inputs to the roughness bound (no samples, attenuation outside (0, 1) ...)."""


def effective_samples(
    cells: ArrayLike,
    ph_lab: ArrayLike,
    stage_angles: ArrayLike,
    cap_deg: float = DEFAULT_CAP_DEG,
) -> float:
    """Effective sample count ``N`` near the specular lobe (see the module docstring).

    Parameters
    ----------
    cells : (n, 3) array_like, radians
        ``(th, td, pd)`` of each pair.
    ph_lab : (n,) array_like, radians
        Lab half-vector azimuth of each pair.
    stage_angles : (r,) array_like, radians
        Stage angles of the plan.
    cap_deg : float
        Half-angle of the cap around the normal (in half-vector space) that counts as the
        specular lobe, degrees, in (0, 90].

    Returns
    -------
    float
        ``N_cap * 4 pi / Omega_cap``; 0 when no half vector falls in the cap.
    """
    if not 0.0 < cap_deg <= 90.0:
        raise RoughnessError(f"specular cap {cap_deg} deg must be in (0, 90]")
    c = np.asarray(cells, dtype=float).reshape(-1, 3)
    ph = np.asarray(ph_lab, dtype=float).reshape(-1)
    alpha = np.asarray(stage_angles, dtype=float).reshape(-1)
    if c.shape[0] == 0 or alpha.size == 0:
        raise RoughnessError("need at least one pair and one stage angle to count samples")
    if ph.size != c.shape[0]:
        raise RoughnessError(f"{c.shape[0]} cells but {ph.size} lab azimuths; give one per pair")
    cap = math.radians(cap_deg)
    inside = c[:, 0] <= cap + 1e-12
    h = geo.spherical_to_direction(
        np.repeat(c[inside, 0], alpha.size), (ph[inside, None] - alpha[None, :]).ravel()
    )
    # Half vectors closer than 0.01 deg are the same sample (e.g. every angle of a th = 0 pair).
    key = np.round(h / 1.7e-4).astype(np.int64)
    n_cap = np.unique(key, axis=0).shape[0] if key.size else 0
    omega = 2.0 * math.pi * (1.0 - math.cos(cap))
    return n_cap * 4.0 * math.pi / omega


def resolvable_degree(n_samples: float) -> int:
    """Largest spherical-harmonic degree ``l*`` with ``(l* + 1)^2 <= N`` (0 when ``N < 4``)."""
    if n_samples < 0:
        raise RoughnessError(f"sample count must be non-negative, got {n_samples}")
    return max(math.isqrt(math.floor(n_samples)) - 1, 0)


def roughness_threshold(degree: int, attenuation: float = DEFAULT_ATTENUATION) -> float:
    """``alpha' = sqrt(-ln t) / l*``; inf when ``l* = 0`` (no lobe width is resolvable)."""
    if not 0.0 < attenuation < 1.0:
        raise RoughnessError(f"attenuation t = {attenuation} must be in (0, 1)")
    if degree <= 0:
        return math.inf
    return math.sqrt(-math.log(attenuation)) / degree


@dataclass(frozen=True)
class RoughnessBound:
    """Resolvable-roughness bound of a plan.

    Attributes
    ----------
    n_effective : float
        Effective sample count ``N`` (full-sphere equivalent).
    degree : int
        ``l*``.
    alpha_min : float
        ``alpha'``: the smallest resolvable microfacet roughness (``alpha = r^2``).
    attenuation : float
        ``t`` used.
    cap_deg : float
        Specular cap used, degrees.
    """

    n_effective: float
    degree: int
    alpha_min: float
    attenuation: float
    cap_deg: float

    def resolves(self, alpha: float) -> bool:
        """Whether a fitted roughness ``alpha`` is at or above the bound (trustworthy)."""
        return alpha >= self.alpha_min


def roughness_bound(
    cells: ArrayLike,
    ph_lab: ArrayLike,
    stage_angles: ArrayLike,
    *,
    attenuation: float = DEFAULT_ATTENUATION,
    cap_deg: float = DEFAULT_CAP_DEG,
) -> RoughnessBound:
    """math.md 11 bound for a design measured at ``stage_angles``.

    Parameters
    ----------
    cells : (n, 3) array_like, radians
    ph_lab : (n,) array_like, radians
    stage_angles : (r,) array_like, radians
    attenuation : float
        ``t`` in (0, 1) (default 0.5).
    cap_deg : float
        Specular cap for :func:`effective_samples`.
    """
    n_eff = effective_samples(cells, ph_lab, stage_angles, cap_deg)
    degree = resolvable_degree(n_eff)
    return RoughnessBound(
        n_effective=n_eff,
        degree=degree,
        alpha_min=roughness_threshold(degree, attenuation),
        attenuation=attenuation,
        cap_deg=cap_deg,
    )


def below_bound_warning(alpha_fit: float, bound: RoughnessBound) -> str | None:
    """A warning for a fitted roughness the plan cannot resolve, else ``None``."""
    if bound.resolves(alpha_fit):
        return None
    return (
        f"fitted roughness alpha = {alpha_fit:.3g} is below the resolvable bound "
        f"alpha' = {bound.alpha_min:.3g} of this plan (N = {bound.n_effective:.0f} effective "
        f"specular samples, l* = {bound.degree}); the lobe may be sharper than measured: add "
        "pairs near the specular direction or more stage angles"
    )


def bound_angles(rotations: int, span_deg: float = 360.0) -> NDArray[np.float64]:
    """The stage angles :func:`roughness_bound` counts for a scan of ``rotations`` uniform
    angles over ``span_deg`` (180 or 360 degrees).

    Returns
    -------
    (r,) or (2 r,) radians
        ``k span / r``; over half a turn with each angle's half-turn copy, since a
        twofold-symmetric specimen reads the same there (the scans' default assumption,
        :data:`gonio.brdf.reconstruction.samples.DEFAULT_SPAN_DEG`).
    """
    angles = uniform_stage_angles(rotations, span=np.deg2rad(span_deg))
    return angles if span_deg >= 360.0 else np.concatenate([angles, angles + np.pi])
