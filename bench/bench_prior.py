"""The joint fit's prior along ph chosen per scan: which empirical-Bayes variant pays (issue 9).

Run from the project root (needs mitsuba and ``../shared/data/rgl`` like ``bench_unseen.py``,
whose readings, designs and caches it reuses)::

    nice -n 5 .venv/bin/python bench/bench_prior.py [--sets fresh panel measured]
        [--variants ...] [--r 8] [--seed-offset 0] [--span 180|360] [--design-span 180|360]

Selection sets only by default (the project never tunes on its test set):

* ``fresh``: materials drawn with the library's own recipes but another seed
  (``library_specs(seed=7)``; 8 brushed metals, 6 fabrics, 4 metals: "fresh-aniso"; 6
  isotropic ones: "fresh-iso"), in no basis; the default basis and its default n = 10 design;
* ``fresh12``: the same materials scanned with each of 12 designs (the default basis' and the
  11 leave-one-measured-out bases', each fitted with its own basis), for design rules;
* ``panel``: the seven synthetic materials held out of the panel basis
  (:mod:`gonio.brdf.design.heldout`), its default design;
* ``measured``: the 11 measured materials, each with the basis that leaves it out (as
  ``bench_unseen.py``).

``--sets TEST`` runs the six mitsuba specimens (the benchmark's test set; look only after the
choice is made). Every scan: 1 % noise, r uniform stage angles over ``--span`` degrees (default
half a turn, as ``bench_unseen.py``), the pairs designed for 8 angles over ``--design-span``
(default: ``--span``; the designs are ``bench_unseen``'s, cached with their arc). Variants are
factors on the harmonics of the learnt prior (``m = 0`` keeps 1), chosen per scan by marginal
likelihood (``s2`` profiled) over a grid: ``lib scan`` / ``lib scan-bands`` call ``reconstruct``
with ``rho="scan"`` (the default: one factor on ``m > 0``, kept at most 1) /
``rho="scan-bands"`` (harmonics ``m <= 2`` and ``m > 2`` each with its own factor); the others
are fitted here with :func:`solve_joint`: ``flat ext`` (one factor, grid to 256, no cap),
``bandB`` (factors for ``0 < m <= B`` and ``m > B``, grid 1/64..16; ``ext``: low band to 256,
``hicap1``: high band at most 1), ``band3 2|8`` (three bands), ``tilt`` (``rho (m / 2)^beta``),
``eta`` (the noise-to-prior ratio chosen too, from 2.5..320; ``capped``: the factor kept at most
1). Output: per material, each variant's log_rmse with its factors (at m = 2, 8, 20) and eta;
then the mean per set.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any

import bench_unseen as bu
import numpy as np
import scipy.linalg

from gonio.brdf.materials import library
from gonio.brdf.models import analytic as bm
from gonio.brdf.reconstruction.basis import Basis, default_basis, remap
from gonio.brdf.reconstruction.blas import one_blas_thread
from gonio.brdf.reconstruction.joint import JOINT_ETA, JOINT_LAM, joint_prior, solve_joint
from gonio.brdf.reconstruction.posterior import profiled_log_marginal
from gonio.brdf.reconstruction.samples import DEFAULT_SPAN_DEG
from gonio.brdf.reconstruction.tabulate import expand_table
from gonio.brdf.tables import geometry as geo
from gonio.brdf.tables import metrics
from gonio.brdf.tables.table import BRDFTable

FRESH = {"brushed-metal": 8, "fabric": 6, "metal": 4, "plastic": 2, "paint": 2,
         "diffuse": 1, "retro": 1}


@dataclass
class Case:
    name: str
    kind: str
    truth: BRDFTable
    specimen: Any
    basis: Basis
    cells: np.ndarray
    ph: np.ndarray
    seed: int


def fresh_cases() -> list[Case]:
    b = default_basis()
    cells, ph = bu.design(b, 10)
    out = []
    count: dict[str, int] = {}
    for i, s in enumerate(library.library_specs(seed=7)):
        if count.get(s.family, 0) >= FRESH[s.family]:
            continue
        count[s.family] = count.get(s.family, 0) + 1
        vals = bu._cached(f"fresh7-{s.name}", lambda s=s: np.asarray(
            bm.tabulate_valid(s.model), dtype=np.float32))
        if vals.shape[1] == 1:
            vals = np.repeat(vals, geo.N_PH, axis=1)
        kind = "fresh-aniso" if s.family in ("brushed-metal", "fabric", "metal") else "fresh-iso"
        out.append(Case(f"f7-{s.name}", kind, bu._full_table(vals, s.name), s.model, b, cells,
                        ph, 700 + i))
    return out


def fresh12_cases() -> list[Case]:
    """The fresh materials scanned with each of 12 designs: the default basis' and the 11
    leave-one-measured-out bases' (each fitted with its own basis; the fresh materials are in
    none), so a design rule is judged over designs, not one draw (docs/science.md 7.2.1)."""
    base = fresh_cases()
    bases = [base[0].basis] + [default_basis(exclude=m.exclude) for m in bu.measured_materials()]
    out = []
    for j, b in enumerate(bases):
        cells, ph = bu.design(b, 10)
        out += [replace(c, name=f"{c.name}@{j}", kind=f"{c.kind} x12", basis=b, cells=cells,
                        ph=ph) for c in base]
    return out


def panel_cases() -> list[Case]:
    from gonio.brdf.design.heldout import _panel

    pb, synth, _ = _panel()
    cells, ph = bu.design(pb, 10)
    return [Case(t.name, "panel", t, t, pb, cells, ph, 500 + i) for i, t in enumerate(synth)]


def measured_cases() -> list[Case]:
    out = []
    for i, m in enumerate(bu.measured_materials()):
        b = default_basis(exclude=m.exclude)
        cells, ph = bu.design(b, 10)
        out.append(Case(m.name, "measured", m.truth, m.specimen, b, cells, ph, 100 + i))
    return out


def aniso_cases() -> list[Case]:
    b = default_basis()
    cells, ph = bu.design(b, 10)
    return [Case(m.name, "TEST-aniso", m.truth, m.specimen, b, cells, ph, 111 + i)
            for i, m in enumerate(bu.aniso_materials())]


# ---------------------------------------------------------------------------- fits
class Scan:
    """Remapped readings and per-harmonic reading kernels of one scan."""

    def __init__(self, c: Case, alpha: np.ndarray, vals: np.ndarray, eta: float = JOINT_ETA):
        b = c.basis
        th, td, pd = c.cells.T
        rows, weights = b.neighbours(th, td, pd)
        self.Qt = np.einsum("nj,njk->nk", weights, b.Q[rows])
        self.fmed = (weights * b.f_med[rows]).sum(axis=1)[:, None, None]
        self.mu = (weights * b.mu[rows]).sum(axis=1)[:, None, None]
        ci, co = geo.cell_cosines(th, td, pd)
        self.w = np.maximum(ci * co, b.eps)[:, None, None]
        self.b = b
        self.Y = remap(vals, self.fmed, self.w, b.eps) - self.mu
        self.ph_read = c.ph[:, None] - alpha[None, :]
        self.P = joint_prior(b, JOINT_LAM / eta)
        n, r = self.ph_read.shape
        M = self.P.shape[0]
        A = np.matmul(np.matmul(self.Qt[None], self.P), self.Qt.T[None])  # (M, n, n)
        q = np.repeat(np.arange(n), r)
        Z = np.exp(-1j * self.ph_read.ravel()[:, None] * np.arange(M))  # (N, M)
        cosm = (Z[:, None, :] * np.conj(Z)[None, :, :]).real  # (N, N, M)
        self.Gm = np.moveaxis(cosm, -1, 0) * A[:, q][:, :, q]  # (M, N, N)
        self.y = self.Y.reshape(n * r, -1)
        self.eta = eta
        # A per-pair nugget: what the basis cannot represent at a pair's cell, the same at
        # every stage angle (covariance 1 between two readings of one pair, 0 otherwise).
        self.nug = np.kron(np.eye(n), np.ones((r, r)))
        self.Z = Z.reshape(n, r, M)
        self.tau = 0.0
        # Mirror cells: a specimen symmetric about the axis at ph0 reads at (th, td, pd, ph)
        # what it reads at (th, td, pi - pd, 2 ph0 - ph) (reflection plus reciprocity).
        rows2, w2 = b.neighbours(th, td, np.mod(np.pi - pd, np.pi))
        self.Qm = np.einsum("nj,njk->nk", w2, b.Q[rows2])
        fm = (w2 * b.f_med[rows2]).sum(axis=1)[:, None, None]
        mm = (w2 * b.mu[rows2]).sum(axis=1)[:, None, None]
        self.Ym = remap(vals, fm, self.w, b.eps) - mm
        self.ph0 = None

    def loglik(self, s: np.ndarray, eta: float) -> float:
        G = np.tensordot(s, self.Gm, axes=1) + self.tau * self.nug
        G[np.diag_indices_from(G)] += eta
        return profiled_log_marginal(G, self.y)

    def augmented(self, ph0: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Readings, rows and ph with the mirrored virtual readings about ``ph0``."""
        return (np.concatenate([self.Y, self.Ym]), np.concatenate([self.Qt, self.Qm]),
                np.concatenate([self.ph_read, 2 * ph0 - self.ph_read]))

    def _aug_cov(self, s: np.ndarray, ph0: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Noise-free prior covariance of [x(q, ph_a); x(q', 2 ph0 - ph_a)], rows, ph."""
        _, Qt, phr = self.augmented(ph0)
        n2, r = phr.shape
        A = np.matmul(np.matmul(Qt[None], self.P * s[:, None, None]), Qt.T[None])
        q = np.repeat(np.arange(n2), r)
        Z = np.exp(-1j * phr.ravel()[:, None] * np.arange(M))
        G = np.einsum("am,bm,mab->ab", Z, np.conj(Z), A[:, q][:, :, q]).real
        return G, Qt, phr

    def cond_loglik(self, s: np.ndarray, eta: float, ph0: float, slack: float
                    ) -> tuple[float, np.ndarray | None]:
        """ln p(y | x' - x = delta) (s2 profiled) under the stationary prior, where the
        mirror readings x' must equal the real ones up to the remap's offset delta (with
        variance ``slack``), and the weights beta (2N, C) of the conditional posterior mean."""
        G, _, _ = self._aug_cov(s, ph0)
        N = self.y.shape[0]
        C = self.y.shape[1]
        T = np.block([[np.eye(N), np.zeros((N, N))], [-np.eye(N), np.eye(N)]])
        cov = T @ G @ T.T
        cov[np.diag_indices(2 * N)] += np.concatenate([np.full(N, eta), np.full(N, slack)])
        delta = (self.Ym - self.Y).reshape(N, C)
        obs = np.concatenate([self.y, delta])
        try:
            cf = scipy.linalg.cho_factor(cov, lower=True)
            cz = scipy.linalg.cho_factor(cov[N:, N:], lower=True)
        except np.linalg.LinAlgError:
            return -np.inf, None
        sol = scipy.linalg.cho_solve(cf, obs)
        quad = float(np.sum(obs * sol)) - float(np.sum(delta * scipy.linalg.cho_solve(cz, delta)))
        logdet = 2.0 * (float(np.sum(np.log(np.diag(cf[0]))))
                        - float(np.sum(np.log(np.diag(cz[0])))))
        ll = -0.5 * N * C * np.log(max(quad / (N * C), 1e-300)) - 0.5 * C * logdet
        return ll, T.T @ sol

    def cond_table(self, s: np.ndarray, beta: np.ndarray, ph0: float) -> np.ndarray:
        _, Qt, phr = self._aug_cov(s, ph0)
        n2, r = phr.shape
        C = beta.shape[1]
        Z = np.exp(-1j * phr[:, :, None] * HARM)  # (2n, r, M)
        U = np.matmul(Z.transpose(0, 2, 1), beta.reshape(n2, r, C))  # (2n, M, C)
        B = np.matmul(Qt.T[None], U.transpose(1, 0, 2))  # (M, K, C)
        PB = np.matmul(self.P * s[:, None, None], B)
        E = np.exp(1j * geo.PH_GRID[:, None] * HARM[None, :])
        K = Qt.shape[1]
        coef = (E @ PB.reshape(M, K * C)).real.reshape(-1, K, C).transpose(1, 0, 2)
        return expand_table(self.b, np.moveaxis(coef, -1, 0))

    def loglik_aug(self, s: np.ndarray, eta: float, ph0: float) -> float:
        Y, Qt, phr = self.augmented(ph0)
        n2, r, C = Y.shape
        A = np.matmul(np.matmul(Qt[None], self.P * s[:, None, None]), Qt.T[None])
        q = np.repeat(np.arange(n2), r)
        Z = np.exp(-1j * phr.ravel()[:, None] * np.arange(M))
        G = np.einsum("am,bm,mab->ab", Z, np.conj(Z), A[:, q][:, :, q]).real
        G[np.diag_indices_from(G)] += eta
        return profiled_log_marginal(G, Y.reshape(-1, C))

    def table(self, s: np.ndarray, eta: float) -> np.ndarray:
        if getattr(self, "cond", None) is not None:
            ph0, slack = self.cond
            _, beta = self.cond_loglik(s, eta, ph0, slack)
            assert beta is not None
            return self.cond_table(s, beta, ph0)
        if self.ph0 is not None:
            Y, Qt, phr = self.augmented(self.ph0)
            jf = solve_joint(Y, Qt, phr, self.P * s[:, None, None], eta)
            return expand_table(self.b, np.moveaxis(jf.coef, -1, 0))
        if self.tau == 0.0:
            jf = solve_joint(self.Y, self.Qt, self.ph_read, self.P * s[:, None, None], eta)
            return expand_table(self.b, np.moveaxis(jf.coef, -1, 0))
        # The basis part of the posterior mean only (the nugget is not in the table).
        G = np.tensordot(s, self.Gm, axes=1) + self.tau * self.nug
        G[np.diag_indices_from(G)] += eta
        n, r, C = self.Y.shape
        beta = scipy.linalg.solve(G, self.y, assume_a="pos").reshape(n, r, C)
        U = np.matmul(self.Z.transpose(0, 2, 1), beta)  # (n, M, C)
        B = np.matmul(self.Qt.T[None], U.transpose(1, 0, 2))  # (M, K, C)
        PB = np.matmul(self.P * s[:, None, None], B)
        E = np.exp(1j * geo.PH_GRID[:, None] * HARM[None, :])
        K = self.Qt.shape[1]
        coef = (E @ PB.reshape(M, K * C)).real.reshape(-1, K, C).transpose(1, 0, 2)
        return expand_table(self.b, np.moveaxis(coef, -1, 0))


M = 37
HARM = np.arange(M)
RHO = np.geomspace(1 / 64, 16.0, 11)


def spec(rho: float, beta: float = 0.0, m0: float = 2.0) -> np.ndarray:
    s = np.ones(M)
    s[1:] = rho * (HARM[1:] / m0) ** beta
    return s


def band(lo: float, hi: float, mb: int) -> np.ndarray:
    s = np.ones(M)
    s[1:mb + 1] = lo
    s[mb + 1:] = hi
    return s


def best(scan: Scan, cands: list[tuple[np.ndarray, float]]) -> tuple[np.ndarray, float]:
    lls = [scan.loglik(s, e) for s, e in cands]
    return cands[int(np.argmax(lls))]


def v_base(scan: Scan) -> tuple[np.ndarray, float]:
    s, e = best(scan, [(spec(r), JOINT_ETA) for r in RHO])
    return (s if s[2] < 1.0 else spec(1.0)), e


def v_plain(scan: Scan) -> tuple[np.ndarray, float]:
    return spec(1.0), JOINT_ETA


def mk_tilt(betas: tuple[float, ...], cap: bool) -> Callable[[Scan], tuple[np.ndarray, float]]:
    def f(scan: Scan) -> tuple[np.ndarray, float]:
        s, e = best(scan, [(spec(r, bb), JOINT_ETA) for r in RHO for bb in betas])
        if cap:
            # flat part as before: keep the learnt level when rho >= 1, but the tilt
            r = s[2]
            if r >= 1.0:
                s = s / r
        return s, e
    return f


def mk_band(mb: int, cap: bool) -> Callable[[Scan], tuple[np.ndarray, float]]:
    def f(scan: Scan) -> tuple[np.ndarray, float]:
        s, e = best(scan, [(band(lo, hi, mb), JOINT_ETA) for lo in RHO for hi in RHO])
        if cap:
            s = np.minimum(s, 1.0)
        return s, e
    return f


def mk_eta(etas: tuple[float, ...], cap: bool) -> Callable[[Scan], tuple[np.ndarray, float]]:
    def f(scan: Scan) -> tuple[np.ndarray, float]:
        s, e = best(scan, [(spec(r), et) for r in RHO for et in etas])
        if cap and s[2] >= 1.0:
            s = spec(1.0)
        return s, e
    return f


def mk_fixed(s_fn: Callable[[], np.ndarray]) -> Callable[[Scan], tuple[np.ndarray, float]]:
    def f(scan: Scan) -> tuple[np.ndarray, float]:
        return s_fn(), JOINT_ETA
    return f


RHO_EXT = np.geomspace(1 / 64, 256.0, 13)


def mk_band2(mb: int, grid: np.ndarray, etas: tuple[float, ...] = (JOINT_ETA,),
             cap_lo: bool = False) -> Callable[[Scan], tuple[np.ndarray, float]]:
    def f(scan: Scan) -> tuple[np.ndarray, float]:
        s, e = best(scan, [(band(lo, hi, mb), et) for lo in grid for hi in grid for et in etas])
        return s, e
    return f


def mk_flat(grid: np.ndarray) -> Callable[[Scan], tuple[np.ndarray, float]]:
    def f(scan: Scan) -> tuple[np.ndarray, float]:
        return best(scan, [(spec(r), JOINT_ETA) for r in grid])
    return f


def mk_band_grid(mb: int, glo: np.ndarray, ghi: np.ndarray
                 ) -> Callable[[Scan], tuple[np.ndarray, float]]:
    def f(scan: Scan) -> tuple[np.ndarray, float]:
        return best(scan, [(band(lo, hi, mb), JOINT_ETA) for lo in glo for hi in ghi])
    return f


def band3(a: float, b: float, c: float, m1: int, m2: int) -> np.ndarray:
    s = np.ones(M)
    s[1:m1 + 1] = a
    s[m1 + 1:m2 + 1] = b
    s[m2 + 1:] = c
    return s


def mk_band3(m1: int, m2: int, g: np.ndarray) -> Callable[[Scan], tuple[np.ndarray, float]]:
    def f(scan: Scan) -> tuple[np.ndarray, float]:
        return best(scan, [(band3(a, b, c, m1, m2), JOINT_ETA) for a in g for b in g for c in g])
    return f


RHO7 = np.geomspace(1 / 64, 16.0, 7)
RHO_LO = np.geomspace(1 / 64, 256.0, 15)
RHO_CAP1 = np.geomspace(1 / 64, 1.0, 7)
#: Nugget variances, as fractions of the readings' mean prior variance (``diag G``, ``s = 1``).
TAUS = (0.0, 0.01, 0.03, 0.1, 0.3, 1.0, 3.0)


def mk_nugget(inner: Callable[[Scan], tuple[np.ndarray, float]]
              ) -> Callable[[Scan], tuple[np.ndarray, float]]:
    """``inner``'s factors, then the nugget's variance (prior units) by marginal likelihood;
    the scan's ``tau`` is left set for the fit."""
    def f(scan: Scan) -> tuple[np.ndarray, float]:
        scan.tau = 0.0
        s, e = inner(scan)
        unit = float(np.mean(np.einsum("mii->i", scan.Gm)))
        lls = []
        for t in TAUS:
            scan.tau = t * unit
            lls.append(scan.loglik(s, e))
        scan.tau = TAUS[int(np.argmax(lls))] * unit
        return s, e
    return f


PH0 = np.arange(36) * np.pi / 36


def mk_mirror(inner: Callable[[Scan], tuple[np.ndarray, float]], fine: bool = False
              ) -> Callable[[Scan], tuple[np.ndarray, float]]:
    """``inner``'s factors, then the mirror axis by the likelihood of the augmented readings
    (= how well the stationary prior predicts the mirrored readings from the real ones)."""
    def f(scan: Scan) -> tuple[np.ndarray, float]:
        scan.ph0 = None
        s, e = inner(scan)
        lls = [scan.loglik_aug(s, e, p0) for p0 in PH0]
        scan.ph0 = float(PH0[int(np.argmax(lls))])
        if fine:  # 1 degree steps around the best 5 degree axis
            near = scan.ph0 + np.deg2rad(np.arange(-4.0, 5.0))
            lls = [scan.loglik_aug(s, e, p0) for p0 in near]
            scan.ph0 = float(near[int(np.argmax(lls))])
        return s, e
    return f


SLACKS = (0.25, 1.0, 4.0)


def mk_cond(inner: Callable[[Scan], tuple[np.ndarray, float]],
            slacks: tuple[float, ...] = SLACKS, fine: bool = False
            ) -> Callable[[Scan], tuple[np.ndarray, float]]:
    """``inner``'s factors; then mirror symmetry about ph0 (5 degree grid) with a slack
    (x eta), or none, whichever gives the readings the largest marginal likelihood."""
    def f(scan: Scan) -> tuple[np.ndarray, float]:
        scan.cond = None
        s, e = inner(scan)
        best_ll, best = scan.loglik(s, e), None
        for p0 in PH0:
            for sl in slacks:
                ll, _ = scan.cond_loglik(s, e, float(p0), sl * e)
                if ll > best_ll:
                    best_ll, best = ll, (float(p0), sl * e)
        if fine and best is not None:
            for p0 in best[0] + np.deg2rad([-4.0, -3, -2, -1, 1, 2, 3, 4]):
                for sl in slacks:
                    ll, _ = scan.cond_loglik(s, e, float(p0), sl * e)
                    if ll > best_ll:
                        best_ll, best = ll, (float(p0), sl * e)
        scan.cond = best
        return s, e
    return f


BETAS = (-1.0, -0.5, 0.0, 0.5, 1.0, 1.5, 2.0)
VARIANTS: dict[str, Callable[[Scan], tuple[np.ndarray, float]]] = {
    "plain": v_plain,
    "base(scan rho)": v_base,
    "tilt free": mk_tilt(BETAS, cap=False),
    "tilt capped": mk_tilt(BETAS, cap=True),
    "band4 free": mk_band(4, cap=False),
    "band4 capped": mk_band(4, cap=True),
    "band8 free": mk_band(8, cap=False),
    "flat ext": mk_flat(RHO_EXT),
    "band2 ext": mk_band2(2, RHO_EXT),
    "band4 ext": mk_band2(4, RHO_EXT),
    "band6 ext": mk_band2(6, RHO_EXT),
    "band4 ext+eta": mk_band2(4, RHO_EXT, (5.0, 10.0, 20.0, 40.0, 80.0)),
    "band2 free": mk_band2(2, RHO),
    "band6 free": mk_band2(6, RHO),
    "band4 free+eta": mk_band2(4, RHO, (10.0, 20.0, 40.0, 80.0)),
    "band2 loext": mk_band_grid(2, RHO_LO, RHO),
    "band2 hicap1": mk_band_grid(2, RHO, RHO_CAP1),
    "band2 loext hicap1": mk_band_grid(2, RHO_LO, RHO_CAP1),
    "band3 2|8": mk_band3(2, 8, RHO7),
    "nugget": mk_nugget(v_base),
    "band2+nugget": mk_nugget(mk_band2(2, RHO)),
    "mirror": mk_mirror(v_base),
    "mirror+bands": mk_mirror(mk_band2(2, RHO)),
    "mirror fine": mk_mirror(v_base, fine=True),
    "sym ML": mk_cond(v_base),
    "sym ML+bands": mk_cond(mk_band2(2, RHO)),
    "sym wide": mk_cond(v_base, (0.25, 1.0, 4.0, 16.0, 64.0)),
    "sym wide fine": mk_cond(v_base, (0.25, 1.0, 4.0, 16.0, 64.0), fine=True),
    "mirror fine+bands": mk_mirror(mk_band2(2, RHO), fine=True),
    "eta free": mk_eta((2.5, 5.0, 10.0, 20.0, 40.0, 80.0, 160.0, 320.0), cap=False),
    "eta capped": mk_eta((2.5, 5.0, 10.0, 20.0, 40.0, 80.0, 160.0, 320.0), cap=True),
}


LIB = ("lib scan", "lib scan-bands", "lib scan+mirror", "lib scan-bands+mirror")


def run(cases: list[Case], variants: list[str], r: int, seed_offset: int = 0) -> None:
    alpha = bu.scan_angles(r)
    res: dict[str, dict[str, float]] = {v: {} for v in variants}
    t0 = time.perf_counter()
    for c in cases:
        m = bu.Material(c.name, c.kind, c.truth, c.specimen, ())
        vals = bu.read(m, c.cells, c.ph, alpha, c.seed + seed_offset)
        scan = Scan(c, alpha, vals)
        line = []
        for v in variants:
            if v in LIB:
                from gonio.brdf.reconstruction.reconstruct import reconstruct

                how = v.split()[1].split("+")
                rec = reconstruct(c.basis, c.cells, c.ph, alpha, vals, rho=how[0],
                                  symmetry="scan" if "mirror" in how else None)
                t = rec.table.values
                lo = rec.settings["prior_rho"]
                s, e = spec(lo), JOINT_ETA
                s[3:] = rec.settings.get("prior_rho_high", lo)
                if rec.settings.get("mirror_axis_deg") is not None:
                    e = rec.settings["mirror_axis_deg"] + rec.settings["mirror_slack"] / 1000
            else:
                scan.tau = 0.0
                scan.ph0 = None
                scan.cond = None
                s, e = VARIANTS[v](scan)
                t = scan.table(s, e)
                if scan.cond is not None:
                    e = float(np.rad2deg(scan.cond[0])) + scan.cond[1] / 1000
                if scan.ph0 is not None:
                    e = float(np.rad2deg(scan.ph0))  # shown as eta=ph0 in degrees
                if scan.tau:
                    unit = float(np.mean(np.einsum("mii->i", scan.Gm)))
                    e = -scan.tau / unit  # shown as eta=-tau (fraction of the prior variance)
            err = metrics.log_rmse(t, c.truth)
            res[v][c.name] = err
            line.append(f"{v} {err:.4f} (s2={s[2]:.3g} s8={s[8]:.3g} s20={s[20]:.3g} eta={e:g})")
        print(f"  {c.kind} {c.name}: " + "; ".join(line)
              + f" ({time.perf_counter() - t0:.0f} s)", flush=True)
    kinds = sorted({c.kind for c in cases})
    print("\n| variant | " + " | ".join(f"{k} ({sum(c.kind == k for c in cases)})"
                                      for k in kinds) + " |")
    print("|---" * (len(kinds) + 1) + "|")
    for v in variants:
        print(f"| {v} | " + " | ".join(
            f"{np.mean([res[v][c.name] for c in cases if c.kind == k]):.4f}" for k in kinds)
            + " |")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--sets", nargs="*", default=["fresh", "panel"])
    ap.add_argument("--variants", nargs="*", default=list(VARIANTS))
    ap.add_argument("--r", type=int, default=8)
    ap.add_argument("--seed-offset", type=int, default=0)
    ap.add_argument("--span", type=float, choices=[180.0, 360.0], default=DEFAULT_SPAN_DEG,
                    help="arc (degrees) of the uniform stage angles")
    ap.add_argument("--design-span", type=float, choices=[180.0, 360.0], default=None,
                    help="arc (degrees) the pair design assumes (default: --span)")
    args = ap.parse_args(argv)
    bu.CHOOSE["objective"] = bu.DEFAULT_OBJECTIVE  # the default design, as bench_unseen
    bu.SPAN["scan"] = args.span
    bu.SPAN["design"] = args.span if args.design_span is None else args.design_span
    print(f"$ {' '.join(['python', *sys.argv])}")
    print(f"r = {args.r} stage angles over {bu.SPAN['scan']:g} deg, pairs designed for "
          f"{bu.SPAN['design']:g} deg")
    make = {"fresh": fresh_cases, "fresh12": fresh12_cases, "panel": panel_cases,
            "measured": measured_cases, "TEST": aniso_cases}
    cases = [c for s in args.sets for c in make[s]()]
    with one_blas_thread():
        run(cases, args.variants, args.r, args.seed_offset)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
