"""Benchmark: reconstruction quality on materials gonio has never seen (issue 9).

Run from the project root (needs mitsuba: ``pip install 'gonio[rgl]'``)::

    nice -n 5 .venv/bin/python bench/bench_unseen.py [--method joint|vf] [--measured-weight W]

Materials
---------
* **Measured** (isotropic): the RGL files in ``../shared/data/rgl``, one material per file
  except the two ``irid_flake_paint1`` files, which are one swatch. Each is tested
  leave-one-measured-material-out: the basis is ``default_basis(exclude=[material])`` (the
  synthetic library plus every *other* shipped measured material), so neither file of the
  held-out material is ever trained on. The truth is the file evaluated with mitsuba
  (:func:`gonio.brdf.materials.rgl.read_rgl`); the test file is the standard (non-``fine``) one.
* **Anisotropic**: six specimens made with an independent renderer (mitsuba 3, variant
  ``scalar_rgb``): ``roughconductor`` with mitsuba's measured IORs and ``alpha_u != alpha_v``,
  ``principled`` with ``anisotropic``, and diffuse + brushed-conductor blends, each turned by an
  arbitrary holder angle. The readings are mitsuba evaluated at the exact pair directions
  (not a table lookup); the truth table is mitsuba on gonio's grid. Basis: ``default_basis()``.

Every scan: 1 % relative noise (seed per material), pairs designed on the material's own
training basis (cached per basis and :func:`fit_fingerprint`): ``--design kappa`` is V&F's
condition-number search
(``design_pairs(basis, n, RigConstraints(), objective="kappa")``), ``--design posterior``
``objective="posterior"`` (the joint fit's expected error, :mod:`gonio.brdf.design.posterior`;
the default, as ``design_pairs``' ``DEFAULT_OBJECTIVE``),
with ``--design posterior-spread-alias`` that design with both corrections (``slope="spread",
aliasing=True``); ``r`` uniform stage angles ``k span / r`` over ``--span`` (180 or 360
degrees; default :data:`~gonio.brdf.reconstruction.samples.DEFAULT_SPAN_DEG`, half a turn, which
for a twofold-symmetric specimen shows each pair ``r`` distinct azimuths instead of ``r / 2``),
the pairs designed for ``r = 8`` angles over ``--design-span`` (default: ``--span``). Converted
tables and designs (named with the design's arc) are cached under ``<gonio cache>/bench-unseen``.

Rows: gonio default (n = 10, r = 8; ``--pairs N``: N pairs), V&F's path (``method="vf"``),
each industrial preset with 8 rotations, n = 5 / 20, r = 4 / 16 (all over ``--span``), V&F's
adaptive plan (e = 0.1, start 8, budget 16 rotations; readings used; the adaptive rows always
scan a full turn, their midpoint
rule is periodic over 360 degrees), and the basis ceiling (the best the basis can do with every
cell known: least squares of every slice on the basis), and the representation's own limit
(the truth tabulated on gonio's grid, ``log_rmse`` 0). Columns: mean ``log_rmse`` (headline,
lower is better), mean ``log_psnr`` (dB) and mean HDR-FLIP over the measured and the
anisotropic materials. HDR-FLIP (:mod:`gonio.brdf.pictures.appearance`, ``--no-flip`` leaves
it out): every table rendered through gonio's lookup in the standard renderings (a sphere under
four lights) against the truth rendered from mitsuba at each pixel's exact directions (the
anisotropic specimens' BSDFs; for the measured materials the RGL file through mitsuba's
``measured`` plugin), cached per material. Below: HDR-FLIP per material and row with each
set's mean, per-material log_rmse of the default row against the best preset, and how often
the self-estimate ``predicted_log_rmse`` is within x2 of the truth.
"""

from __future__ import annotations

import argparse
import functools
import hashlib
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from gonio.brdf.design.colourtargets import DEFAULT_COLOUR_WEIGHT
from gonio.brdf.design.pairs import DEFAULT_OBJECTIVE
from gonio.brdf.design.presets import get_preset, preset_names
from gonio.brdf.design.renderweight import DEFAULT_CELL_MIX, render_weight
from gonio.brdf.materials.library import cache_root
from gonio.brdf.reconstruction.basis import Basis, default_basis, remap, row_weight
from gonio.brdf.reconstruction.errors import ReconstructionError
from gonio.brdf.reconstruction.reconstruct import reconstruct
from gonio.brdf.reconstruction.samples import (
    DEFAULT_SPAN_DEG,
    NoiseModel,
    pair_directions,
    uniform_stage_angles,
)
from gonio.brdf.reconstruction.tabulate import expand_table
from gonio.brdf.tables import geometry as geo
from gonio.brdf.tables import metrics
from gonio.brdf.tables.table import BRDFTable

ROOT = Path(__file__).resolve().parents[1]
RGL_DIR = ROOT.parent / "shared" / "data" / "rgl"
CACHE = cache_root() / "bench-unseen"
MASK = geo.valid_mask()

#: (name, mitsuba dict, holder angle in degrees). Holder angles are arbitrary, off the grid.
ANISO: list[tuple[str, dict[str, Any], float]] = [
    ("mi-conductor-Au", {"type": "roughconductor", "material": "Au", "distribution": "ggx",
                         "alpha_u": 0.08, "alpha_v": 0.30}, 17.0),
    ("mi-conductor-Cu", {"type": "roughconductor", "material": "Cu",
                         "distribution": "beckmann", "alpha_u": 0.25, "alpha_v": 0.07}, 128.0),
    ("mi-principled-metal", {"type": "principled", "metallic": 0.8, "roughness": 0.35,
                             "anisotropic": 0.8,
                             "base_color": {"type": "rgb", "value": [0.8, 0.55, 0.3]}}, 63.0),
    ("mi-principled-plastic", {"type": "principled", "metallic": 0.0, "roughness": 0.3,
                               "anisotropic": 0.6, "specular": 0.6,
                               "base_color": {"type": "rgb", "value": [0.15, 0.35, 0.6]}},
     211.0),
    ("mi-blend-brushed-Al", {"type": "blendbsdf", "weight": 0.6,
                             "bsdf_0": {"type": "diffuse",
                                        "reflectance": {"type": "rgb", "value": [0.5, 0.1, 0.1]}},
                             "bsdf_1": {"type": "roughconductor", "material": "Al",
                                        "alpha_u": 0.06, "alpha_v": 0.35}}, 94.0),
    ("mi-blend-brushed-Ag", {"type": "blendbsdf", "weight": 0.3,
                             "bsdf_0": {"type": "diffuse",
                                        "reflectance": {"type": "rgb", "value": [0.2, 0.5, 0.3]}},
                             "bsdf_1": {"type": "roughconductor", "material": "Ag",
                                        "alpha_u": 0.4, "alpha_v": 0.1}}, 302.5),
]


# ---------------------------------------------------------------------------- materials
def _mitsuba() -> Any:
    import mitsuba as mi

    mi.set_variant("scalar_rgb")  # the llvm variants crash on this machine's LLVM
    return mi


class MitsubaSpecimen:
    """A mitsuba BSDF turned by ``holder_deg`` about the normal; ``eval`` in 1/sr."""

    def __init__(self, spec: dict[str, Any], holder_deg: float) -> None:
        self.mi = _mitsuba()
        self.bsdf = self.mi.load_dict(spec)
        self.holder = np.deg2rad(holder_deg)

    def eval(self, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        mi = self.mi
        # The specimen is turned by +holder: its own frame sees directions turned back.
        a = geo.rotate_z(np.asarray(wi), -self.holder)
        b = geo.rotate_z(np.asarray(wo), -self.holder)
        ctx, si = mi.BSDFContext(), mi.SurfaceInteraction3f()
        out = np.empty((a.shape[0], 3))
        for k in range(a.shape[0]):
            si.wi = mi.Vector3f(*a[k])
            v = self.bsdf.eval(ctx, si, mi.Vector3f(*b[k]))
            out[k] = (v[0], v[1], v[2])
        with np.errstate(divide="ignore", invalid="ignore"):
            f = out / b[:, 2:3]  # mitsuba returns f cos(theta_o)
        return np.where(np.isfinite(f) & (f > 0), f, 0.0)


def _full_table(values_valid: np.ndarray, name: str) -> BRDFTable:
    """(3, P, 7861) -> table; P = 1 (isotropic) is broadcast to 72 slices."""
    full = np.full((3, geo.N_PH, *geo.SLICE_SHAPE), np.nan, dtype=np.float32)
    full[:, :, MASK] = values_valid
    return BRDFTable(full, ("R", "G", "B"), name)


def _cached(key: str, make: Callable[[], np.ndarray]) -> np.ndarray:
    path = CACHE / f"{key}.npy"
    if path.is_file():
        return np.load(path)
    arr = make()
    path.parent.mkdir(parents=True, exist_ok=True)
    np.save(path, arr)
    return arr


@dataclass
class Material:
    name: str
    kind: str  # "measured" or "aniso"
    truth: BRDFTable
    specimen: Any  # eval(wi, wo)
    exclude: tuple[str, ...]  # shipped measured materials to hold out of its basis
    #: What the FLIP column's reference renderings evaluate (``eval(wi, wo)`` at each pixel's
    #: exact directions); None: ``specimen``.
    reference: Any = None


def measured_materials() -> list[Material]:
    from gonio.brdf.materials.rgl import read_rgl

    files = sorted(RGL_DIR.glob("*.bsdf"))
    out = []
    for p in files:
        if p.stem.endswith("_fine_rgb"):
            continue  # same swatch as the standard file: held out together, tested once
        group = p.stem.removesuffix("_rgb")
        vals = _cached(f"rgl-{p.stem}", lambda p=p: np.asarray(
            read_rgl(p).values[:, :1][:, :, MASK], dtype=np.float32))
        t = _full_table(vals, group)
        # The file itself evaluated by mitsuba at every pixel's directions is the rendered
        # truth (its own, finer parametrisation); the readings stay lookups in ``t``.
        ref = MitsubaSpecimen({"type": "measured", "filename": str(p)}, 0.0)
        out.append(Material(group, "measured", t, t, (group,), ref))
    return out


def aniso_materials(specimens: list[tuple[str, dict[str, Any], float]] | None = None
                    ) -> list[Material]:
    """Mitsuba specimens ``(name, spec, holder angle in degrees)`` as materials (truth tables
    cached by name and recipe); ``specimens`` defaults to :data:`ANISO`."""
    th, td, pd = geo.grid_angles()
    out = []
    for name, spec, holder in (ANISO if specimens is None else specimens):
        s = MitsubaSpecimen(spec, holder)
        digest = hashlib.sha256(repr((spec, holder)).encode()).hexdigest()[:12]

        def make(s: MitsubaSpecimen = s) -> np.ndarray:
            vals = np.empty((3, geo.N_PH, int(MASK.sum())), dtype=np.float32)
            for k, ph in enumerate(geo.PH_GRID):
                wi, wo = geo.half_diff_to_directions(th[MASK], ph, td[MASK], pd[MASK])
                vals[:, k] = s.eval(wi, wo).T
            return vals

        vals = _cached(f"{name}-{digest}", make)
        out.append(Material(name, "aniso", _full_table(vals, name), s, ()))
    return out


# ---------------------------------------------------------------------------- scans
def basis_id(b: Basis) -> str:
    return hashlib.sha256(np.ascontiguousarray(b.Q).tobytes()).hexdigest()[:16]


@functools.cache
def fit_fingerprint() -> str:
    """A digest of what the current reconstruction reports on a fixed probe scan.

    Cached designs (:func:`design`) and ``calibrate_log_rmse.py``'s cached rows and designs
    are reused only while this is unchanged, so a change of the default joint fit (its prior,
    empirical Bayes, witnesses) or of the default design regenerates them without anyone
    remembering to. The probe is a library material read with the MA68 preset at 8 angles on
    the default basis, plus the expected-error design of 5 pairs for 4 angles on that basis;
    values are rounded to 6 significant digits so that BLAS-level jitter does not count.
    Computed once per process (a few seconds).
    """
    from gonio.brdf.design.constraints import RigConstraints
    from gonio.brdf.design.pairs import design_pairs
    from gonio.brdf.materials.library import get_material, library_specs
    from gonio.brdf.reconstruction.samples import NoiseModel, simulate_samples

    b = default_basis()
    cells, ph = get_preset("MA68").cells()
    alpha = uniform_stage_angles(8)
    model = get_material(library_specs()[0].name)
    vals = simulate_samples(model, cells, ph, alpha, noise=NoiseModel(0.01, seed=7))
    rec = reconstruct(b, cells, ph, alpha, vals)
    d = design_pairs(b, 5, RigConstraints(), objective="posterior", rotations=4)
    probe = np.r_[np.asarray(rec.table.values, dtype=float)[:, ::7, ::97].ravel(),
                  rec.expected_log_rmse, rec.mahalanobis, rec.cv_sample_error,
                  np.ravel(d.cells), np.ravel(d.ph_lab)]
    probe = np.nan_to_num(probe)
    text = ",".join(f"{v:.6g}" for v in probe)
    return hashlib.sha256(f"{basis_id(b)}|{text}".encode()).hexdigest()[:12]


CHOOSE: dict[str, Any] = {"k": 1, "objective": "kappa"}
#: Arcs (degrees) of the scans' uniform stage angles (``--span``) and of the ones the pair
#: design assumes (``--design-span``).
SPAN: dict[str, float] = {"scan": DEFAULT_SPAN_DEG, "design": DEFAULT_SPAN_DEG}


#: ``--design`` names: the bench's cache tag and how the pairs are made.
DESIGNS = {
    "kappa": "",  # V&F's condition-number search
    # the expected-error design (median slope, no aliasing, the renderings' weighting at
    # DEFAULT_CELL_MIX: design_pairs' default)
    "posterior": "-posterior",
    "posterior-spread-alias": "-posterior-spread-alias",  # with both corrections
    # The design a lab gets when it asks for colour at the MA98 geometries (docs/colour.md).
    "posterior-colour-MA98": "-posterior-colour-MA98",
}


#: The colour design's weight (``--colour-weight``), for ``--design posterior-colour-MA98``.
COLOUR_WEIGHT = {"w": DEFAULT_COLOUR_WEIGHT}


def design(b: Basis, n: int) -> tuple[np.ndarray, np.ndarray]:
    from gonio.brdf.design.constraints import RigConstraints
    from gonio.brdf.design.pairs import design_pairs
    from gonio.brdf.design.posterior import posterior_design

    k = CHOOSE["k"]
    obj = CHOOSE["objective"]
    span = SPAN["design"]
    tag = f"{DESIGNS[obj]}{f'-choose{k}' if k > 1 else ''}-span{span:g}"
    if obj == "posterior-colour-MA98":
        # Always the weight's value: a design cached under the default's name would be reused
        # after the default changed (10 to 100).
        tag += f"-w{COLOUR_WEIGHT['w']:g}"
    # Keyed by the code's fingerprint too: the basis alone would reuse designs made by older
    # design code. The probe runs the expected-error design (and so the placement every
    # objective shares), not the condition-number search itself.
    path = CACHE / f"design-{basis_id(b)}-n{n}{tag}-{fit_fingerprint()}.npz"
    if path.is_file():
        with np.load(path) as z:
            return z["cells"], z["ph_lab"]
    if obj == "posterior":
        d = design_pairs(b, n, RigConstraints(), objective="posterior", span_deg=span)
    elif obj == "posterior-colour-MA98":
        from gonio.brdf.colour.instruments import geometries
        from gonio.brdf.design.colourtargets import ColourTargets

        g = geometries(["MA98"])
        d = design_pairs(b, n, RigConstraints(), objective="posterior", span_deg=span,
                         colour=ColourTargets(np.stack([x.directions()[0] for x in g]),
                                              np.stack([x.directions()[1] for x in g]),
                                              weight=COLOUR_WEIGHT["w"]))
    elif obj == "posterior-spread-alias":
        d = posterior_design(b, n, RigConstraints(), slope="spread", aliasing=True,
                             span_deg=span, cell_weight=render_weight(),
                             cell_mix=DEFAULT_CELL_MIX)
    elif k > 1:
        from gonio.brdf.design.heldout import choose_design

        d, _err, table = choose_design(
            lambda seed: design_pairs(b, n, RigConstraints(), objective="kappa", seed=seed,
                                      span_deg=span),
            range(k), span_deg=span)
        print(f"  n={n}: candidates (seed, kappa, expected log_rmse) {table}", flush=True)
    else:
        d = design_pairs(b, n, RigConstraints(), objective="kappa", span_deg=span)
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez(path, cells=d.cells, ph_lab=d.ph_lab)
    return np.asarray(d.cells), np.asarray(d.ph_lab)


def read(m: Material, cells: np.ndarray, ph: np.ndarray, alpha: np.ndarray,
         seed: int) -> np.ndarray:
    """Readings at the exact pair directions turned by each stage angle, 1 % noise."""
    wi_lab, wo_lab = pair_directions(cells, ph)
    wi = geo.lab_to_specimen(wi_lab[:, None, :], alpha[None, :]).reshape(-1, 3)
    wo = geo.lab_to_specimen(wo_lab[:, None, :], alpha[None, :]).reshape(-1, 3)
    v = np.asarray(m.specimen.eval(wi, wo), dtype=float).reshape(len(cells), alpha.size, 3)
    v = np.where(np.isfinite(v), np.maximum(v, 0.0), 0.0)
    return NoiseModel(0.01, seed=seed).apply(v)


def ceiling(b: Basis, truth: BRDFTable) -> BRDFTable:
    """Least-squares fit of every slice of ``truth`` on the basis (every cell known)."""
    rows = np.flatnonzero(b.valid)
    x = np.asarray(truth.values, dtype=float).reshape(3, geo.N_PH, geo.N_ROWS)[:, :, rows]
    w = row_weight(b.eps)[rows]
    y = np.nan_to_num(remap(x, b.f_med[rows], w, b.eps), nan=0.0) - b.mu[rows]
    Qv = b.Q[rows]
    coef = np.linalg.lstsq(Qv, y.reshape(-1, rows.size).T, rcond=None)[0]  # (K, 3*72)
    coef = coef.T.reshape(3, geo.N_PH, b.K).transpose(0, 2, 1)
    return BRDFTable.trusted(expand_table(b, coef), ("R", "G", "B"), "ceiling")


@dataclass
class Score:
    log_rmse: float
    log_psnr: float
    flip: float = float("nan")
    predicted: float = float("nan")
    readings: int = 0
    cv_rel: float = float("nan")
    n: int = 0
    r: int = 0


def truth_images(m: Material) -> list[np.ndarray]:
    """The truth's standard renderings (:mod:`gonio.brdf.pictures.appearance`), cached.

    Rendered from ``m.reference`` (or ``m.specimen``) evaluated at each pixel's exact
    directions: mitsuba for every material here, not a lookup in the 5 degree table.
    """
    from gonio.brdf.pictures import appearance

    if m.name not in _TRUTH_IMAGES:
        src = m.reference if m.reference is not None else m.specimen
        key = hashlib.sha256(repr((appearance.APPEARANCE_VIEWS, appearance.APPEARANCE_SIZE,
                                   m.name, m.kind)).encode()).hexdigest()[:12]
        arr = _cached(f"flipref-{m.name}-{key}",
                      lambda: np.stack(appearance.render_appearance(src)))
        _TRUTH_IMAGES[m.name] = list(arr)
    return _TRUTH_IMAGES[m.name]


_TRUTH_IMAGES: dict[str, list[np.ndarray]] = {}


def with_black_level(images: list[np.ndarray], level: float, peak: float) -> list[np.ndarray]:
    """``images`` with ``level * peak`` added to every colour of the sphere's pixels (a floor
    under the rendering, as a display's black or any real surface's faint body gives); the
    background stays black. ``level`` is a fraction of ``peak``, the reference's brightest
    pixel value (radiance units); 0 returns the images as they are."""
    from gonio.brdf.pictures import appearance

    if level == 0:
        return images
    return [np.where(d[..., None], np.asarray(i) + level * peak, np.asarray(i))
            for i, d in zip(images, appearance.drawn_masks(), strict=True)]


def reference_quantiles(m: Material) -> np.ndarray:
    """25th, 50th and 75th percentiles of the truth renderings' pixel luminance (mean of the
    three colours) over the sphere's pixels of the four views, as fractions of the brightest
    pixel value (dimensionless, shape (3,))."""
    from gonio.brdf.pictures import appearance

    ref = truth_images(m)
    peak = max(float(np.nanmax(i)) for i in ref)
    lum = np.concatenate([np.asarray(i).mean(axis=-1)[d]
                          for i, d in zip(ref, appearance.drawn_masks(), strict=True)])
    return np.asarray(np.percentile(lum / peak, [25, 50, 75]))


def flip_of(table: BRDFTable, m: Material) -> float:
    """Mean HDR-FLIP of ``table`` (rendered through gonio's lookup) against the truth; with
    ``--black-level`` both renderings get that floor first (:func:`with_black_level`)."""
    from gonio.brdf.pictures import appearance

    ref, test = truth_images(m), appearance.render_appearance(table)
    level = BLACK["level"]
    if level:
        peak = max(float(np.nanmax(i)) for i in ref)
        ref, test = with_black_level(ref, level, peak), with_black_level(test, level, peak)
    return appearance.standard_flip(ref, test).mean


def score(rec_table: BRDFTable, truth: BRDFTable, rec: Any = None, readings: int = 0,
          m: Material | None = None) -> Score:
    s = Score(metrics.log_rmse(rec_table, truth), metrics.log_psnr(rec_table, truth))
    if m is not None and FLIP["on"]:
        s.flip = flip_of(rec_table, m)
    if rec is not None:
        s.predicted, s.cv_rel = rec.predicted_log_rmse, rec.cv_sample_error
        s.n, s.r = rec.settings["n"], rec.settings["r"]
        s.readings = readings
    return s


def calibrate(rows: dict[str, dict[str, Score]], mats: list[Material]) -> None:
    """Fit ``ln(log_rmse) = a + b ln(cv_sample_error) + c ln(n r)`` on half the materials
    (alternate positions within each kind) and validate on the other half."""
    from gonio.brdf.reconstruction.selfcheck import VF_LOG_RMSE_MODEL

    order = {m.name: i for i, m in enumerate([m for m in mats if m.kind == "measured"])}
    order.update({m.name: i for i, m in enumerate([m for m in mats if m.kind == "aniso"])})
    data = [(order[name] % 2, s) for row, per in rows.items() if not row.startswith("basis")
            for name, s in per.items() if np.isfinite(s.cv_rel) and s.cv_rel > 0]
    fit = [s for half, s in data if half == 0]
    X = np.array([[1.0, np.log(s.cv_rel), np.log(s.n * s.r)] for s in fit])
    y = np.log([s.log_rmse for s in fit])
    coef = np.linalg.lstsq(X, y, rcond=None)[0]
    print(f"\ncalibration (even positions, {len(fit)} scans): VF_LOG_RMSE_MODEL = "
          f"({coef[0]:.3f}, {coef[1]:.3f}, {coef[2]:.3f}); module has {VF_LOG_RMSE_MODEL}")
    for half, label in ((0, "calibration half"), (1, "validation half")):
        ss = [s for h, s in data if h == half]
        pred = np.exp(coef[0]) * np.array([s.cv_rel for s in ss]) ** coef[1] * np.array(
            [s.n * s.r for s in ss], dtype=float) ** coef[2]
        ratio = pred / np.array([s.log_rmse for s in ss])
        print(f"  {label}: {len(ss)} scans, ratio median {np.median(ratio):.2f}, "
              f"within x2 {np.mean((ratio >= 0.5) & (ratio <= 2)):.0%}")


ETA: dict[str, float | None] = {"eta": None, "lam": None}
#: Whether rows get the HDR-FLIP column (``--no-flip`` turns it off).
FLIP: dict[str, bool] = {"on": True}
#: ``--black-level``: a floor added to both renderings before HDR-FLIP, as a fraction of the
#: reference's brightest pixel (0: the standard metric; a diagnostic, science.md 7).
BLACK: dict[str, float] = {"level": 0.0}
#: The representation's own limit: the truth tabulated on gonio's grid, rendered through
#: gonio's lookup, against the truth rendered from mitsuba (log_rmse 0 by definition).
LIMIT_ROW = "truth on gonio's grid (representation limit)"
#: The joint fit's ``rho`` (``--rho``; reconstruct's default when None).
RHO: dict[str, str | None] = {"rho": None, "symmetry": None}


def scan_angles(r: int) -> np.ndarray:
    """``r`` uniform stage angles (radians) over the scans' arc (``SPAN["scan"]``)."""
    return uniform_stage_angles(r, span=np.deg2rad(SPAN["scan"]))


def run_scan(b: Basis, m: Material, cells: np.ndarray, ph: np.ndarray, r: int, seed: int,
             method: str) -> Score:
    alpha = scan_angles(r)
    vals = read(m, cells, ph, alpha, seed)
    extra = ({k: v for k, v in RHO.items() if v is not None} if method == "joint" else {})
    rec = reconstruct(b, cells, ph, alpha, vals, method=method,  # type: ignore[arg-type]
                      eta=ETA["eta"] if method == "joint" else None,
                      lam=ETA["lam"] if method == "joint" else None, **extra)
    return score(rec.table, m.truth, rec, vals.shape[0] * r, m)


def run_adaptive(b: Basis, m: Material, cells: np.ndarray, ph: np.ndarray, seed: int,
                 method: str, r0: int = 8, budget: int = 16, joint_e: float | None = None,
                 everywhere: bool = False) -> Score:
    """V&F Sec. 6: start with r0 rotations, refine where PCHIP mispredicts (e = 0.1); with
    ``joint_e``, refine where the joint fit's leave-one-angle-out log error exceeds it."""
    from gonio.brdf.reconstruction.reconstruct import refine_angles
    from gonio.plans.adaptive import adaptive_refinement

    angles = list(np.rad2deg(uniform_stage_angles(r0)))
    vals = read(m, cells, ph, np.deg2rad(angles), seed)
    for rnd in range(6):
        if joint_e is None:
            new = adaptive_refinement(angles, vals, 0.1, 1.0, budget - len(angles))
        else:
            rec = reconstruct(b, cells, ph, np.deg2rad(angles), vals)
            assert rec.angle_log_errors is not None
            new = refine_angles(angles, rec.angle_log_errors, joint_e, 1.0,
                                budget - len(angles), everywhere=everywhere)
        if not new:
            break
        extra = read(m, cells, ph, np.deg2rad(new), seed + 1000 * (rnd + 1))
        angles += list(new)
        vals = np.concatenate([vals, extra], axis=1)
    rec = reconstruct(b, cells, ph, np.deg2rad(angles), vals, method=method)  # type: ignore[arg-type]
    return score(rec.table, m.truth, rec, vals.shape[0] * len(angles), m)


def flip_table(rows: dict[str, dict[str, Score]], mats: list[Material],
               order: list[str]) -> None:
    """Per-material HDR-FLIP of each row (columns), and each set's mean."""
    short = [r.split(" (")[0].split(" n=")[0] if r != LIMIT_ROW else "grid limit"
             for r in order]
    print("\nHDR-FLIP against the truth rendered by mitsuba (lower is better)")
    print("| material | " + " | ".join(short) + " |")
    print("|---" * (1 + len(order)) + "|")
    for m in mats:
        print(f"| {m.name} | " + " | ".join(f"{rows[r][m.name].flip:.3f}" for r in order)
              + " |")
    for k in ("measured", "aniso"):
        ks = [m for m in mats if m.kind == k]
        if ks:
            print(f"| **mean {k} ({len(ks)})** | " + " | ".join(
                f"**{np.mean([rows[r][m.name].flip for m in ks]):.3f}**" for r in order) + " |")


# ---------------------------------------------------------------------------- main
def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--method", default="joint", choices=["joint", "vf"],
                    help="gonio's default reconstruction method to report as 'gonio'")
    ap.add_argument("--measured-weight", type=float, default=None,
                    help="weight of the shipped measured materials (0: synthetic basis only)")
    ap.add_argument("--full", action="store_true",
                    help="also the n = 5 / 20, r = 4 / 16 and adaptive rows")
    ap.add_argument("--only", choices=["measured", "aniso"], default=None)
    ap.add_argument("--fixed-design", action="store_true",
                    help="design the pairs once on the synthetic basis (for weight studies)")
    ap.add_argument("--eta", type=float, default=None, help="override the joint fit's eta")
    ap.add_argument("--lam", type=float, default=None, help="override the joint fit's lam")
    ap.add_argument("--adaptive-e", type=float, nargs="*", default=[0.01],
                    help="thresholds of the joint adaptive rows (log_rmse units)")
    ap.add_argument("--choose", type=int, default=1, metavar="K",
                    help="pick each design among K seeds by expected held-out error "
                         "(gonio.brdf.design.heldout; its panel contains the measured materials, "
                         "so use with --only aniso for a clean test)")
    ap.add_argument("--design", choices=list(DESIGNS), default=DEFAULT_OBJECTIVE,
                    help="pair design (default: design_pairs' DEFAULT_OBJECTIVE): V&F's "
                         "condition-number search, the joint fit's expected "
                         "error (gonio.brdf.design.posterior), or that design with the slope "
                         "averaged over the basis' spread and aliasing as noise, or the "
                         "expected-error design asked for colour at the MA98 geometries")
    ap.add_argument("--pairs", type=int, default=10,
                    help="pairs of gonio's design (default 10, the benchmark's)")
    ap.add_argument("--colour-weight", type=float, default=DEFAULT_COLOUR_WEIGHT,
                    help="with --design posterior-colour-MA98: the colour targets' weight")
    ap.add_argument("--rho", choices=["scan", "scan-bands"], default=None,
                    help="the joint fit's prior along ph: one factor on the varying harmonics "
                         "('scan', reconstruct's default) or one per band ('scan-bands')")
    ap.add_argument("--symmetry", choices=["scan"], default=None,
                    help="the joint fit's mirror symmetry chosen per scan (reconstruct's "
                         "symmetry='scan'; default: none)")
    ap.add_argument("--span", type=float, choices=[180.0, 360.0], default=DEFAULT_SPAN_DEG,
                    help="arc (degrees) of every row's uniform stage angles (default: "
                         "DEFAULT_SPAN_DEG; the adaptive rows always scan a full turn)")
    ap.add_argument("--design-span", type=float, choices=[180.0, 360.0], default=None,
                    help="arc (degrees) the pair design assumes (default: --span)")
    ap.add_argument("--asymmetric-library", action="store_true",
                    help="train the bases on the library's families without twofold symmetry "
                         "too (default_basis(asymmetric=True); science.md 7.4)")
    ap.add_argument("--no-flip", action="store_true",
                    help="leave out the HDR-FLIP columns (rendering costs about 1 s a row)")
    ap.add_argument("--black-level", type=float, default=0.0, metavar="FRACTION",
                    help="diagnostic: add this fraction of the reference's brightest pixel to "
                         "the sphere's pixels of both renderings before HDR-FLIP (default 0, "
                         "the standard metric; e.g. 1e-4, a 10,000:1 display)")
    ap.add_argument("--calibrate", action="store_true",
                    help="fit predicted_log_rmse's model on half the materials, check the rest")
    args = ap.parse_args(argv)
    if not 0 <= args.black_level < 1:
        ap.error(f"--black-level {args.black_level:g}: give a fraction of the brightest pixel "
                 "in [0, 1), e.g. 1e-4")
    print(f"$ {' '.join(['python', *sys.argv])}")
    t0 = time.perf_counter()
    mats: list[Material] = []
    if args.only != "aniso":
        mats += measured_materials() if RGL_DIR.is_dir() else []
    if args.only != "measured":
        mats += aniso_materials()
    print(f"materials ready in {time.perf_counter() - t0:.0f} s: "
          + ", ".join(m.name for m in mats))

    rows: dict[str, dict[str, Score]] = {}

    def put(row: str, m: Material, s: Score) -> None:
        rows.setdefault(row, {})[m.name] = s

    presets = {p: get_preset(p).cells() for p in preset_names()}
    ETA["eta"], ETA["lam"] = args.eta, args.lam
    FLIP["on"] = not args.no_flip
    BLACK["level"] = args.black_level
    if BLACK["level"] and FLIP["on"]:
        print(f"\nHDR-FLIP with a floor of {BLACK['level']:g} x the reference's brightest pixel "
              "added to both renderings (a diagnostic, science.md 7.0.2). The reference's "
              "pixels over the sphere, as a fraction of its brightest (the floor hides what "
              "lies below it):")
        for m in mats:
            q = reference_quantiles(m)
            print(f"  {m.name}: 25th percentile {q[0]:.1e}, median {q[1]:.1e}, 75th {q[2]:.1e}")
    RHO["rho"], RHO["symmetry"] = args.rho, args.symmetry
    CHOOSE["k"] = args.choose
    CHOOSE["objective"] = args.design
    COLOUR_WEIGHT["w"] = args.colour_weight
    SPAN["scan"] = args.span
    SPAN["design"] = args.span if args.design_span is None else args.design_span
    print(f"stage angles over {SPAN['scan']:g} deg, pairs designed for {SPAN['design']:g} deg")
    asym = {"asymmetric": True} if args.asymmetric_library else {}
    fixed = default_basis(measured_weight=0.0, **asym) if args.fixed_design else None
    other = "vf" if args.method == "joint" else "joint"
    main_row = f"gonio ({args.method}) n={args.pairs} r=8"
    for i, m in enumerate(mats):
        b = default_basis(exclude=m.exclude, measured_weight=args.measured_weight, **asym)
        seed = 100 + i
        cells, ph = design(fixed or b, args.pairs)
        put(main_row, m, run_scan(b, m, cells, ph, 8, seed, args.method))
        try:
            put(f"{other} path n={args.pairs} r=8", m,
                run_scan(b, m, cells, ph, 8, seed, other))
        except ReconstructionError as exc:  # V&F's path refuses half a turn on an odd prior
            print(f"  {m.name}: {other} path refused: {str(exc)[:80]}...", flush=True)
            put(f"{other} path n={args.pairs} r=8", m, Score(float("nan"), float("nan")))
        for p, (pc, pph) in presets.items():
            put(f"{p} ({len(pc)} pairs) r=8", m, run_scan(b, m, pc, pph, 8, seed, args.method))
        if args.full:
            for n in (5, 20):
                c2, p2 = design(fixed or b, n)
                put(f"gonio n={n} r=8", m, run_scan(b, m, c2, p2, 8, seed, args.method))
            for r in (4, 16):
                put(f"gonio n={args.pairs} r={r}", m,
                    run_scan(b, m, cells, ph, r, seed, args.method))
            # The adaptive plans insert midpoints on a full turn, whatever --span says.
            turn = "" if SPAN["scan"] == 360 else ", full turn"
            put(f"adaptive V&F e=0.1, 8->16{turn}", m,
                run_adaptive(b, m, cells, ph, seed, args.method))
            for e in args.adaptive_e:
                put(f"adaptive joint e={e}, 8->16{turn}", m,
                    run_adaptive(b, m, cells, ph, seed, args.method, joint_e=e))
                put(f"adaptive joint e={e} everywhere, 8->16{turn}", m,
                    run_adaptive(b, m, cells, ph, seed, args.method, joint_e=e, everywhere=True))
        put("basis ceiling (every cell)", m, score(ceiling(b, m.truth), m.truth, m=m))
        put(LIMIT_ROW, m, score(m.truth, m.truth, m=m))
        print(f"  {m.name}: {rows[main_row][m.name].log_rmse:.4f} "
              f"({time.perf_counter() - t0:.0f} s)", flush=True)

    kinds = [k for k in ("measured", "aniso") if any(m.kind == k for m in mats)]
    head = "".join(f" | {k} ({sum(m.kind == k for m in mats)}) log_rmse / log_psnr dB"
                   f"{' / HDR-FLIP' if FLIP['on'] else ''}" for k in kinds)
    print(f"\n| row{head} | readings |")
    print("|---" * (2 + len(kinds)) + "|")
    for row, per in rows.items():
        cells_txt = ""
        for k in kinds:
            ss = [per[m.name] for m in mats if m.kind == k]
            cells_txt += (f" | {np.mean([s.log_rmse for s in ss]):.4f} / "
                          f"{np.mean([s.log_psnr for s in ss]):.1f}")
            if FLIP["on"]:
                cells_txt += f" / {np.mean([s.flip for s in ss]):.3f}"
        rd = np.mean([s.readings for s in per.values()])
        print(f"| {row}{cells_txt} | {rd:.0f} |" if rd else f"| {row}{cells_txt} | |")

    preset_rows = [r for r in rows if r.split(" ")[0] in preset_names()]
    if FLIP["on"]:
        flip_table(rows, mats, [main_row, f"{other} path n={args.pairs} r=8", *preset_rows,
                                "basis ceiling (every cell)", LIMIT_ROW])
    print("\n| material | gonio log_rmse | best preset | predicted_log_rmse | ceiling |")
    print("|---|---|---|---|---|")
    wins = within = 0
    for m in mats:
        g = rows[main_row][m.name]
        best_row = min(preset_rows, key=lambda r: rows[r][m.name].log_rmse)
        best = rows[best_row][m.name].log_rmse
        wins += g.log_rmse < best
        ratio = g.predicted / g.log_rmse
        within += 0.5 <= ratio <= 2.0
        print(f"| {m.name} | {g.log_rmse:.4f} | {best:.4f} ({best_row.split(' ')[0]}) | "
              f"{g.predicted:.4f} (x{ratio:.2f}) | "
              f"{rows['basis ceiling (every cell)'][m.name].log_rmse:.4f} |")
    print(f"\ngonio beats the best preset on {wins} of {len(mats)}; "
          f"predicted_log_rmse within x2 on {within} of {len(mats)}")
    if args.calibrate:
        calibrate(rows, mats)
    print(f"total {time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
