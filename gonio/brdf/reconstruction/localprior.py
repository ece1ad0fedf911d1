"""Local priors: the joint fit leans on the folded-in material its readings favour.

The learnt prior along ``ph`` (:attr:`Basis.ph_prior`) is one covariance over the whole
training library, so what the readings leave undetermined is filled in with the library's
average. A basis with measured (or user) tables folded in also holds each of those tables' own
isotropic second moment (:attr:`Basis.local_priors`, ``m = 0`` only: the ``(th, td, pd)`` shape of
a material, not how it varies along ``ph``). For a scan, each candidate prior replaces the
isotropic harmonic by an even blend of the library's and one local prior,
``P_0' = (1 - s) P_0 + s L_g`` with ``s =`` :data:`LOCAL_SHARE`; the candidate with the largest
marginal likelihood of the readings (the prior's scale profiled out, the scan's own anisotropy
factors) is used when it beats the library's own prior by strong evidence (:data:`EVIDENCE`),
and the library's prior otherwise (docs/science.md 7.2.3). A
specimen like one of the folded-in materials is then filled in with that material's shape where
no pair looks: a felt like the measured felt, a matte paper like the measured matte paint.

Local priors are not tried with the asymmetric default basis (the one a scan switches to when
its specimen is found without twofold symmetry, docs/science.md 7.4):
the folded-in tables are isotropic measured materials, the least like such a specimen, and
leaning on them made the auto-arc path's asymmetric specimens worse (0.0887 -> 0.0907 mean
``log_rmse`` on bench_asymmetric's choice set).

Only ``m = 0`` is replaced: the varying harmonics stay the library's, so an anisotropic
specimen keeps the anisotropy the whole library taught. The candidates cost one Cholesky
factor of the ``(n r) x (n r)`` readings' covariance each.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gonio.brdf.reconstruction.basis import Basis
from gonio.brdf.reconstruction.posterior import ScanPosterior

FloatArray = np.ndarray

#: A local prior is used only when it raises the log marginal likelihood of the readings by at
#: least ``ln(EVIDENCE) + ln(G)`` over the library's prior (``G`` candidates): a Bayes factor of
#: 20, "strong" on Kass & Raftery's scale, after paying for having tried ``G`` of them. Without it
#: a glossy plastic of the choice set leaned on a measured paint for a gain of 1.2 and doubled
#: its error (docs/science.md 7.2.3).
EVIDENCE = 20.0

#: A pair whose light and sensor lie within this angle of one plane through the normal
#: (``pd`` within it of 0 or 180 degrees) reads in the plane of incidence.
IN_PLANE_TOL_DEG = 10.0
#: Local priors are tried only when at least this share of the pairs reads out of the plane of
#: incidence. Readings in that plane see one slice of each ``(th, td)`` profile; a prior
#: chosen from them decides every other plane, and on the benchmark it decided them worse:
#: MA98 (11 of its 19 pairs in the plane) lost 1.3 % ``log_rmse`` on the measured materials
#: and 18 % on the anisotropic specimens with local priors, while the designed pairs (none in
#: the plane) gained (docs/science.md 7.2.3). The instrument presets (MA68, BYK-mac,
#: MultiFX10: every pair in the plane; MA98) therefore keep the library's prior.
MIN_OUT_OF_PLANE_SHARE = 0.5

#: Share of the local prior in the blended isotropic harmonic (chosen on the choice set of
#: docs/science.md 7.2.3 between 0.1 and 0.5; a share chosen per scan by marginal likelihood
#: from 0.25 / 0.5 / 0.75 did no better there).
LOCAL_SHARE = 0.5


@dataclass(frozen=True)
class LocalPick:
    """A local prior chosen for one scan.

    Attributes
    ----------
    name : the folded-in material whose isotropic second moment the prior leans on
    gain : log marginal likelihood of the readings under the blended prior minus under the
        library's own, per three channels (natural log units; at least ``ln(EVIDENCE G)``)
    prior : (M, K, K) the joint fit's per-harmonic prior with the blended ``m = 0``
    """

    name: str
    gain: float
    prior: FloatArray


def blended_isotropic(P0: FloatArray, local: FloatArray, share: float = LOCAL_SHARE
                      ) -> FloatArray:
    """``(1 - share) P0 + share local``: the isotropic harmonic (K, K) leaning on ``local``."""
    return (1.0 - share) * np.asarray(P0, dtype=float) + share * np.asarray(local, dtype=float)


def blended_prior(P: FloatArray, local: FloatArray, share: float = LOCAL_SHARE) -> FloatArray:
    """The joint fit's prior ``P`` (M, K, K) with ``P_0`` blended with ``local`` (K, K)."""
    out = np.array(P, dtype=float)
    out[0] = blended_isotropic(out[0], local, share)
    return out


def out_of_plane_share(cells: FloatArray) -> float:
    """Share of the pairs (n, 3) ``(th, td, pd)`` radians that read out of the plane of
    incidence (``pd`` further than :data:`IN_PLANE_TOL_DEG` from 0 and 180 degrees)."""
    pd = np.mod(np.rad2deg(np.asarray(cells, dtype=float)[:, 2]), 180.0)
    away = np.minimum(pd, 180.0 - pd) > IN_PLANE_TOL_DEG
    return float(np.mean(away)) if away.size else 0.0


def layout_takes_local_priors(cells: FloatArray) -> bool:
    """Whether a scan of these pairs may lean on a local prior (:data:`MIN_OUT_OF_PLANE_SHARE`)."""
    return out_of_plane_share(cells) >= MIN_OUT_OF_PLANE_SHARE


def local_prior_skipped(basis: Basis, cells: FloatArray) -> str | None:
    """Why a scan of ``cells`` (n, 3) with ``basis`` does not try local priors, or ``None``
    when it does (recorded as the fit's ``settings["local_prior_note"]``)."""
    if basis.local_means is None or basis.ph_prior is None or not len(basis.local_names):
        return "the basis holds no folded-in tables"
    if basis.provenance.get("asymmetric_library"):
        return "the asymmetric basis keeps its library prior"
    if not layout_takes_local_priors(cells):
        return "most pairs read in the plane of incidence"
    return None


def choose_local_prior(post: ScanPosterior, basis: Basis,
                       share: float = LOCAL_SHARE) -> LocalPick | None:
    """The local prior the readings favour over the library's own, or ``None``.

    Parameters
    ----------
    post : ScanPosterior
        The scan's posterior under the library's prior (its readings, its chosen anisotropy
        factors and offset).
    basis : Basis
        The basis ``post`` was made with; its :attr:`Basis.local_priors` are the candidates.
    share : float in (0, 1]

    Returns
    -------
    LocalPick or None
        ``None`` when the basis has no local priors or none raises the marginal likelihood by
        the evidence :data:`EVIDENCE` asks for.
    """
    priors = basis.local_priors  # formed from the stored means on each access: once here
    if priors is None or not len(basis.local_names):
        return None
    base = post.log_marginal_isotropic(post.P[0])
    # The likelihood treats the channels as independent draws of one covariance; a table's
    # channels are strongly correlated (the same surface at other wavelengths), so its
    # evidence is counted per three channels, the RGB readings the threshold was chosen on:
    # a 31-band rig does not lean ten times more readily for the same information.
    per_rgb = 3.0 / post.C
    needed = np.log(EVIDENCE) + np.log(len(basis.local_names))
    best: tuple[float, int] | None = None
    for g, local in enumerate(priors):
        ll = post.log_marginal_isotropic(blended_isotropic(post.P[0], local, share))
        if np.isfinite(ll) and (ll - base) * per_rgb >= needed and (best is None
                                                                     or ll > best[0]):
            best = (ll, g)
    if best is None:
        return None
    ll, g = best
    return LocalPick(basis.local_names[g], float((ll - base) * per_rgb),
                     blended_prior(post.P, priors[g], share))
