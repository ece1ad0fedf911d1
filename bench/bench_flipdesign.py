"""Benchmark: the expected-error design weighted towards what the renderings see (issue 23 item 3).

Run from the project root (needs mitsuba and flip-evaluator: ``pip install 'gonio[rgl]'``)::

    nice -n 5 .venv/bin/python bench/bench_flipdesign.py choose [--mix 0 0.25 0.5 0.75 1]
    nice -n 5 .venv/bin/python bench/bench_flipdesign.py test --mix A
    nice -n 5 .venv/bin/python bench/bench_flipdesign.py choose --mix A --seeds 0 1 2
    nice -n 5 .venv/bin/python bench/bench_flipdesign.py fresh --mix A
    nice -n 10 .venv/bin/python bench/bench_flipdesign.py choose --mix 0.5 --no-presets \
        --limits --measured-weight 1 3 --components 64
    nice -n 10 .venv/bin/python bench/bench_flipdesign.py choose --mix 0.5 --no-presets \
        --limits --eps 1e-3 1e-4 1e-5
    nice -n 10 .venv/bin/python bench/bench_flipdesign.py choose --limits \
        --render-basis 0.5 0.9 0.99

The expected-error design (:mod:`gonio.brdf.design.posterior`) weighs the grid's cells as
``log_rmse`` does (by their volume). The standard renderings
(:mod:`gonio.brdf.pictures.appearance`) look at a few thousand of them, each as often as pixels
land on it (:func:`~gonio.brdf.pictures.appearance.render_importance`). ``cell_mix = a`` chooses
the pairs by ``(1 - a)`` times the ``log_rmse`` objective plus ``a`` times the one weighted by
the pixel counts.

Sets (the discipline of docs/science.md 7.2.2):

* **choice** (``choose``): the measured RGL materials at even positions of bench_unseen's
  order (0, 2, ...: six materials) and :data:`CHOICE_ANISO`, five mitsuba specimens made here
  the way bench_unseen makes its six, with other parameters and holder angles, never used
  anywhere else. ``a`` is chosen here, by mean HDR-FLIP subject to ``log_rmse``.
* **test** (``test``): the measured materials at odd positions (five) and bench_unseen's six
  anisotropic specimens; run once with the chosen ``a`` against ``a = 0`` and every preset.
* **second fresh set** (``fresh2``): :data:`FRESH2_FLIP`, eight more twofold-symmetric mitsuba
  specimens written and committed (2026-11-27, the retro-pair study) before any run on them.
* **third fresh set** (``fresh3``): :data:`FRESH3_FLIP`, seven more (the basis-settings
  study of 2026-11-28, below), written and committed before any run of that study.
* **fresh** (``fresh``): :data:`FRESH_FLIP`, ten twofold-symmetric mitsuba specimens written
  and committed (2026-11-27) before any run on them, after the choice of ``a``: narrow and
  wide brushed metals, glossy isotropic metal, clear-coated (layered) paints, paper, satin and
  felt stand-ins, a glossy plastic. Run once, to decide whether ``a`` becomes the default.
  (The even measured materials' rows of the 17 bench_unseen materials are ``choose``'s: same
  designs, seeds and fits, so the same numbers.)

``--retro K --retro-td T`` adds the retro-pair study's designs (:func:`retro_design`): ``K``
forced near-retro specular pairs at ``td = T`` degrees, the rest by the shipped objective
(docs/notes/2026-11-27-retro-pair.md); a bench option, not the product's design.

``--measured-weight W ... --components K ...`` (the basis-settings study of 2026-11-28,
docs/notes/2026-11-28-basis-flip.md) runs every ``(W, K)`` as its own rows: each material's
basis is ``default_basis(K, exclude=..., measured_weight=W)`` (its leave-one-out basis as
always), the design is made on that basis (``--mix`` as given: 0 is not added in this mode;
the design cache is keyed by the basis' own components, so a new basis designs again) and, with
``--limits``, its basis ceiling is a row of its own. The presets read the first setting's basis.
K = 96 needs the synthetic basis of 128 components (built once and cached,
``synthetic_basis(128)``, about a minute once the library is tabulated).

The rule of that study, written and committed before any of its runs: on the **choice** set,
among the settings ``(W, K)`` whose mean ``log_rmse`` stays within 3 % of today's default
(``W = 1``, ``K = 64``, ``cell_mix = 0.5``) on both kinds (measured and mitsuba), pick the one
with the lowest mean HDR-FLIP over the 11; adopt it only if it lowers that mean by at least
0.01 against the default. The basis ceiling rows are recorded for every setting. The chosen
setting and the default are then run **once** on the **test** set; if the chosen one wins
there too (lower mean HDR-FLIP over the 11, mean ``log_rmse`` within 3 % on both kinds), it
is run once on :data:`FRESH3_FLIP` (written and committed before that run) as the final
check.

``--eps E ...`` (the eps study of 2026-11-28, docs/notes/2026-11-28-eps-flip.md) runs every
remap constant ``E`` of the basis (``X = ln((A w + E) / (f_med w + E))``, docs/science.md
section 1; the product's is ``EPS = 1e-3``) as its own rows, crossed with any ``(W, K)``
given. ``E = EPS`` is today's default basis itself. Any other ``E`` builds the synthetic
basis once, ``build_basis(default_library(), K + 32, eps=E)`` (:func:`eps_synthetic`, cached
in the bench's cache keyed by ``E``, K and the library), and folds the shipped measured
tables in as ``default_basis`` does (``fold_in``, leave-one-out per measured material;
:func:`eps_default_basis`). The design is made on each basis (its key holds the basis'
components, so each ``E`` designs again), and the scan is fitted and, with ``--limits``,
projected in that basis' own remap.

The rule of the eps study, written and committed before any of its runs: on the **choice**
set, among the remap constants (1e-3, today's, and 1e-4; 1e-5 if time allows; ``W = 1``,
``K = 64``, ``cell_mix = 0.5`` throughout) whose mean ``log_rmse`` stays within 3 % of
today's (``E = 1e-3``) on both kinds (measured and mitsuba), pick the one with the lowest
mean HDR-FLIP over the 11; adopt it only if it lowers that mean by at least 0.01 against
today's. The basis ceiling rows are recorded for every ``E``. The chosen ``E`` and today's
are then run **once** on the **test** set; if the chosen one wins there too (lower mean
HDR-FLIP over the 11, mean ``log_rmse`` within 3 % on both kinds), it is run once on
:data:`FRESH3_FLIP` (committed 2026-11-28, never run) as the final check. Adopting would
mean a new shipped synthetic basis and every pinned value; if that cannot be done and
checked within the study, a winner is reported as a candidate and the default stays.

``--render-basis A ...`` (the render-weighted basis study of 2026-11-28,
docs/notes/2026-11-28-render-weighted-basis.md) learns the basis with each grid cell weighed
by what the standard renderings see: a weighted PCA of the remapped, centred training matrix,
row ``i`` weighed by ``d_i = (1 - A) + A c_i / mean(c)`` (``c`` the pixel counts of
:func:`~gonio.brdf.pictures.appearance.render_importance`, the map ``cell_mix`` reads; the mean
over the valid cells, so ``d`` averages 1 and ``A = 0`` is today's unweighted PCA). The
rows are scaled by ``sqrt(d)`` before the randomized SVD and the components by
``1 / sqrt(d)`` after (:func:`render_synthetic`, ``K + 32`` components, cached), and the
shipped measured tables are folded in the same weighted way, leaving out the material under
test (:func:`render_default_basis`, weight 1, K = 64). Per material and strength ``A`` it
prints: the scan with pairs designed on that basis (``rw=A``, ``cell_mix`` 0.5); the scan
with today's pairs (designed on today's basis) fitted on that basis (``rw=A, today's
pairs``); with ``--limits``, that basis' ceiling by the same weighted least squares
(``ceiling rw=A``), and today's basis projected by that weighted least squares (``ceiling
today's basis, projection A``). Today's rows (``today``: default basis, default design,
unweighted ceiling) and the grid limit are always printed.

The rule of that study, written and committed before any of its runs: strengths
``A = 0.5, 0.9, 0.99`` (0.99 gives the cells no rendering looks at a hundredth of the
weight of the average cell), ``W = 1``, ``K = 64``, ``cell_mix = 0.5``, on the **choice**
set. The candidates are every ``(A, pairs)`` scan row, ``pairs`` either its own design or
today's. Eligible: mean ``log_rmse`` no more than 2 % above today's on both kinds (measured
and mitsuba). Choice: the lowest mean HDR-FLIP over the 11 among the eligible. Adoption
candidate only if that mean is more than 0.01 below today's. Then the choice and today's run
**once** on :data:`FRESH3_FLIP` (committed 2026-11-28, never run before this study); it
passes only if there too its mean HDR-FLIP over the 7 is lower than today's and its mean
``log_rmse`` no more than 2 % above. The test set is not run by this study. The ceiling rows
are recorded for every ``A`` and are not part of the rule. Adopting (if it passed) would
mean a weighted ``build_basis``/``fold_in`` in the product, a new shipped synthetic basis and
every pinned value; the study only reports it.

``--seeds`` averages each ``a`` over several designs (the greedy started from the k-th best
first pair, :func:`~gonio.brdf.design.posterior.posterior_design`'s ``seed``): whether the
weighting helps on average over designs of nearly equal expected error, or one design.

Everything else as bench_unseen: n = 10 pairs, r = 8 uniform stage angles over half a turn,
1 % noise, the default joint fit, each measured material on a basis that leaves it out, HDR-FLIP
against the truth rendered by mitsuba. Per material it prints ``log_rmse`` and HDR-FLIP of
every ``a`` and every preset.
"""

from __future__ import annotations

import argparse
import hashlib
import inspect
import json
import sys
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import bench_unseen as bu  # the sibling bench (the script's folder is on sys.path)
import numpy as np

import gonio.brdf
from gonio.brdf.design.constraints import RigConstraints, candidate_rows, rows_to_cells
from gonio.brdf.design.errors import DesignError, FeasibilityError
from gonio.brdf.design.placement import place_pairs
from gonio.brdf.design.posterior import (
    PriorModel,
    _mixed_gram,
    _posterior,
    cell_gram,
    greedy_rows,
    posterior_design,
    prior_model,
)
from gonio.brdf.design.presets import get_preset, preset_names
from gonio.brdf.pictures.appearance import render_importance
from gonio.brdf.reconstruction.basis import (
    _FOLD_EXTRA,
    DEFAULT_COMPONENTS,
    EPS,
    MEASURED_WEIGHT,
    Basis,
    BasisError,
    build_basis,
    default_basis,
    fold_in,
    remap,
    row_weight,
)
from gonio.brdf.reconstruction.tabulate import expand_table
from gonio.brdf.tables import geometry as geo
from gonio.brdf.tables.table import BRDFTable

#: Specimens for the choice set only: bench_unseen's kinds of mitsuba BSDF with other
#: parameters and holder angles (name, mitsuba dict, holder angle in degrees).
CHOICE_ANISO: list[tuple[str, dict[str, Any], float]] = [
    ("mc-conductor-Al", {"type": "roughconductor", "material": "Al", "distribution": "ggx",
                         "alpha_u": 0.15, "alpha_v": 0.05}, 41.0),
    ("mc-conductor-Cr", {"type": "roughconductor", "material": "Cr",
                         "distribution": "beckmann", "alpha_u": 0.12, "alpha_v": 0.4}, 333.0),
    ("mc-principled-red", {"type": "principled", "metallic": 0.0, "roughness": 0.45,
                           "anisotropic": 0.4, "specular": 0.5,
                           "base_color": {"type": "rgb", "value": [0.6, 0.15, 0.1]}}, 155.0),
    ("mc-blend-brushed-Cu", {"type": "blendbsdf", "weight": 0.45,
                             "bsdf_0": {"type": "diffuse",
                                        "reflectance": {"type": "rgb", "value": [0.3, 0.3, 0.5]}},
                             "bsdf_1": {"type": "roughconductor", "material": "Cu",
                                        "alpha_u": 0.05, "alpha_v": 0.2}}, 248.0),
    ("mc-plastic", {"type": "roughplastic", "distribution": "ggx", "alpha": 0.12,
                    "diffuse_reflectance": {"type": "rgb", "value": [0.2, 0.4, 0.1]}}, 0.0),
]


#: The fresh set (see the module notes): never used by any choice; twofold symmetric (no
#: facet tilt or normal map), so half-turn scans are right for them.
FRESH_FLIP: list[tuple[str, dict[str, Any], float]] = [
    ("ff-conductor-W-narrow", {"type": "roughconductor", "material": "W", "distribution": "ggx",
                               "alpha_u": 0.04, "alpha_v": 0.18}, 76.0),
    ("ff-conductor-Ni", {"type": "roughconductor", "material": "Ni_palik",
                         "distribution": "beckmann", "alpha_u": 0.30, "alpha_v": 0.12}, 199.0),
    ("ff-conductor-Ta-iso", {"type": "roughconductor", "material": "Ta", "distribution": "ggx",
                             "alpha": 0.09}, 0.0),
    ("ff-coated-red", {"type": "principled", "metallic": 0.0, "roughness": 0.5,
                       "clearcoat": 1.0, "clearcoat_gloss": 0.9, "specular": 0.4,
                       "base_color": {"type": "rgb", "value": [0.55, 0.08, 0.06]}}, 37.0),
    ("ff-coated-gold-aniso", {"type": "principled", "metallic": 0.9, "roughness": 0.3,
                              "anisotropic": 0.7, "clearcoat": 0.6, "clearcoat_gloss": 0.8,
                              "base_color": {"type": "rgb", "value": [0.9, 0.7, 0.3]}}, 287.0),
    ("ff-paper", {"type": "roughplastic", "distribution": "beckmann", "alpha": 0.45,
                  "diffuse_reflectance": {"type": "rgb", "value": [0.75, 0.75, 0.7]}}, 0.0),
    ("ff-satin", {"type": "principled", "metallic": 0.0, "roughness": 0.6, "sheen": 0.8,
                  "anisotropic": 0.5, "specular": 0.3,
                  "base_color": {"type": "rgb", "value": [0.5, 0.2, 0.35]}}, 143.0),
    ("ff-blend-brushed-Au", {"type": "blendbsdf", "weight": 0.5,
                             "bsdf_0": {"type": "diffuse",
                                        "reflectance": {"type": "rgb", "value": [0.1, 0.1, 0.1]}},
                             "bsdf_1": {"type": "roughconductor", "material": "Au",
                                        "alpha_u": 0.03, "alpha_v": 0.25}}, 321.0),
    ("ff-felt", {"type": "principled", "metallic": 0.0, "roughness": 0.9, "specular": 0.2,
                 "base_color": {"type": "rgb", "value": [0.1, 0.4, 0.2]}}, 0.0),
    ("ff-plastic-glossy", {"type": "roughplastic", "distribution": "ggx", "alpha": 0.05,
                           "diffuse_reflectance": {"type": "rgb", "value": [0.4, 0.05, 0.05]}},
     0.0),
]


#: A second fresh set (the retro-pair study, docs/notes/2026-11-27-retro-pair.md): written and
#: committed before any run on it, after FRESH_FLIP had been seen by the choice of cell_mix;
#: eight twofold-symmetric specimens (no facet tilt or normal map) with other metals,
#: parameters and holder angles than every set above.
FRESH2_FLIP: list[tuple[str, dict[str, Any], float]] = [
    ("f2-conductor-Mo", {"type": "roughconductor", "material": "Mo", "distribution": "ggx",
                         "alpha_u": 0.07, "alpha_v": 0.22}, 112.0),
    ("f2-conductor-Rh-iso", {"type": "roughconductor", "material": "Rh",
                             "distribution": "beckmann", "alpha": 0.16}, 0.0),
    ("f2-conductor-TiN", {"type": "roughconductor", "material": "TiN", "distribution": "ggx",
                          "alpha_u": 0.35, "alpha_v": 0.15}, 268.0),
    ("f2-coated-blue", {"type": "principled", "metallic": 0.0, "roughness": 0.25,
                        "anisotropic": 0.3, "clearcoat": 0.7, "clearcoat_gloss": 0.6,
                        "specular": 0.5,
                        "base_color": {"type": "rgb", "value": [0.1, 0.2, 0.55]}}, 58.0),
    ("f2-principled-bronze", {"type": "principled", "metallic": 1.0, "roughness": 0.2,
                              "anisotropic": 0.5,
                              "base_color": {"type": "rgb", "value": [0.7, 0.45, 0.2]}}, 173.0),
    ("f2-plastic-yellow", {"type": "roughplastic", "distribution": "beckmann", "alpha": 0.2,
                           "diffuse_reflectance": {"type": "rgb", "value": [0.7, 0.6, 0.1]}},
     0.0),
    ("f2-blend-brushed-V", {"type": "blendbsdf", "weight": 0.35,
                            "bsdf_0": {"type": "diffuse",
                                       "reflectance": {"type": "rgb",
                                                       "value": [0.45, 0.45, 0.45]}},
                            "bsdf_1": {"type": "roughconductor", "material": "V_palik",
                                       "alpha_u": 0.2, "alpha_v": 0.04}}, 226.0),
    ("f2-plastic-dark-glossy", {"type": "roughplastic", "distribution": "ggx", "alpha": 0.08,
                                "diffuse_reflectance": {"type": "rgb",
                                                        "value": [0.05, 0.05, 0.08]}}, 0.0),
]


#: A third fresh set (the basis-settings study, docs/notes/2026-11-28-basis-flip.md): written
#: and committed before any run of that study, to be run once, only if a setting wins on the
#: choice and test sets; seven twofold-symmetric specimens (no facet tilt or normal map) with
#: other metals, parameters and holder angles than every set above.
FRESH3_FLIP: list[tuple[str, dict[str, Any], float]] = [
    ("f3-conductor-Ir", {"type": "roughconductor", "material": "Ir", "distribution": "ggx",
                         "alpha_u": 0.10, "alpha_v": 0.30}, 19.0),
    ("f3-conductor-Nb-iso", {"type": "roughconductor", "material": "Nb",
                             "distribution": "beckmann", "alpha": 0.06}, 0.0),
    ("f3-principled-steel", {"type": "principled", "metallic": 1.0, "roughness": 0.35,
                             "anisotropic": 0.6,
                             "base_color": {"type": "rgb", "value": [0.55, 0.56, 0.58]}}, 204.0),
    ("f3-coated-green", {"type": "principled", "metallic": 0.0, "roughness": 0.4,
                         "clearcoat": 0.8, "clearcoat_gloss": 0.7, "specular": 0.5,
                         "base_color": {"type": "rgb", "value": [0.1, 0.45, 0.15]}}, 96.0),
    ("f3-plastic-white", {"type": "roughplastic", "distribution": "ggx", "alpha": 0.3,
                          "diffuse_reflectance": {"type": "rgb", "value": [0.8, 0.8, 0.8]}},
     0.0),
    ("f3-blend-brushed-Be", {"type": "blendbsdf", "weight": 0.6,
                             "bsdf_0": {"type": "diffuse",
                                        "reflectance": {"type": "rgb",
                                                        "value": [0.2, 0.15, 0.1]}},
                             "bsdf_1": {"type": "roughconductor", "material": "Be",
                                        "alpha_u": 0.25, "alpha_v": 0.06}}, 301.0),
    ("f3-satin-pink", {"type": "principled", "metallic": 0.0, "roughness": 0.7, "sheen": 0.5,
                       "anisotropic": 0.3, "specular": 0.6,
                       "base_color": {"type": "rgb", "value": [0.7, 0.3, 0.4]}}, 131.0),
]


def choice_aniso() -> list[bu.Material]:
    """The choice set's mitsuba specimens (truth tables cached like bench_unseen's)."""
    return bu.aniso_materials(CHOICE_ANISO)


def material_sets() -> tuple[list[bu.Material], list[bu.Material]]:
    """(choice, test) as in the module notes."""
    measured = bu.measured_materials()
    choice = measured[0::2] + choice_aniso()
    test = measured[1::2] + bu.aniso_materials()
    return choice, test


def design_code_digest() -> str:
    """Digest of the source of every module the design search can run: the design package
    and the reconstruction package it calls (its prior, rows and arcs), and the table
    geometry. Any edit there designs again; a few needless rebuilds are cheaper than a stale
    design read from the cache."""
    root = Path(gonio.brdf.__file__).parent
    h = hashlib.sha256()
    for path in sorted([*(root / "design").glob("*.py"), *(root / "reconstruction").glob("*.py"),
                        *(root / "tables").glob("*.py")]):
        h.update(path.relative_to(root).as_posix().encode())
        h.update(path.read_bytes())
    return h.hexdigest()[:16]


def design_key(b: Basis, mix: float, importance: np.ndarray, seed: int,
               rig: RigConstraints) -> str:
    """Everything a cached design depends on: the basis, the joint fit and default design
    (``bu.fit_fingerprint``), the source of what the design runs (:func:`design_code_digest`:
    the render-weighted path, which the fingerprint's probe does not run), the rig limits,
    the arc it is designed for, the mix, the seed and, when it weighs cells (``mix > 0``),
    the render-importance map's values, so a change to the renderings designs again."""
    weight = (hashlib.sha256(np.ascontiguousarray(importance, dtype=np.float64).tobytes())
              .hexdigest()[:16] if mix > 0 else "none")
    code = design_code_digest()
    return (f"{bu.basis_id(b)}-{bu.fit_fingerprint()}-{mix:g}-code{code}-{rig!r}"
            f"-span{bu.SPAN['design']:g}-importance{weight}" + (f"-seed{seed}" if seed else ""))


def design(b: Basis, mix: float, importance: np.ndarray, seed: int = 0
           ) -> tuple[np.ndarray, np.ndarray]:
    """10 pairs for 8 angles over half a turn, ``cell_mix = mix``, greedy started from the
    ``seed``-th best first pair; cached by :func:`design_key`."""
    rig = RigConstraints()
    key = design_key(b, mix, importance, seed, rig)
    path = bu.CACHE / f"flipdesign-{hashlib.sha256(key.encode()).hexdigest()[:16]}.npz"
    if path.is_file():
        with np.load(path) as z:
            return z["cells"], z["ph_lab"]
    d = posterior_design(b, 10, rig, span_deg=bu.SPAN["design"], seed=seed,
                         cell_weight=importance if mix > 0 else None, cell_mix=mix)
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez(path, cells=d.cells, ph_lab=d.ph_lab)
    return np.asarray(d.cells), np.asarray(d.ph_lab)


#: Where the second forced near-retro pair may sit (``--retro 2``): ``th`` in degrees; ``td``
#: is the first pair's, ``pd`` any grid value (docs/notes/2026-11-27-retro-pair.md).
RETRO_TH_DEG = np.arange(5.0, 36.0, 5.0)


def _mounts(cells: np.ndarray, rig: RigConstraints) -> bool:
    """Whether ``cells`` mount together under ``rig`` (the check ``posterior_design``'s greedy
    makes at each step)."""
    try:
        place_pairs(cells, rig, ph_step_deg=1.0, orderings=4, seed=0)
    except FeasibilityError:
        return False
    return True


def _read(model: PriorModel, q: np.ndarray) -> PriorModel:
    """``model`` after reading the pairs of basis rows ``q`` ((k, K)): each harmonic's
    posterior, as the colour design's direct pairs condition it."""
    P = np.stack([_posterior(Pm, q, s) for Pm, s in zip(model.P, model.pair_noise(q),
                                                             strict=True)])
    return replace(model, P=P)


def retro_design(b: Basis, importance: np.ndarray, k: int, td_deg: float, n: int = 10,
                 mix: float = 0.5, rig: RigConstraints | None = None
                 ) -> tuple[np.ndarray, np.ndarray]:
    """The study's design (docs/notes/2026-11-27-retro-pair.md): ``k`` forced near-retro
    specular pairs, the other ``n - k`` by the shipped objective.

    Pair 1 is ``(th, td, pd) = (0, td_deg, 0)``; with ``k = 2`` pair 2 is the best near-retro
    cell (``th`` in :data:`RETRO_TH_DEG`, the same ``td``, any grid ``pd``) by the objective
    after pair 1, among those that mount with it. The objective is ``posterior_design``'s with
    ``cell_weight=importance, cell_mix=mix`` (the default's), its prior conditioned on the
    forced pairs; the rest are chosen greedily (greedy seed 0) over ``rig``'s candidate cells,
    each step only among cells that mount with the pairs so far.

    Returns
    -------
    cells : (n, 3) radians, the forced pairs first
    ph_lab : (n,) radians, from ``place_pairs(cells, rig, ph_step_deg=1, seed=0)``

    Raises
    ------
    FeasibilityError
        When the forced pairs, or the design, do not mount under ``rig``.
    """
    if k not in (1, 2):
        raise ValueError(f"k must be 1 or 2, got {k}")
    rig = RigConstraints() if rig is None else rig
    td = np.deg2rad(td_deg)
    model = prior_model(b, span_deg=bu.SPAN["design"])
    model = replace(model, W=_mixed_gram(model, cell_gram(b, importance), mix))
    forced = np.array([[0.0, td, 0.0]])
    if not _mounts(forced, rig):
        raise FeasibilityError(f"the retro pair (0, {td_deg:g}, 0) deg does not mount")
    model = _read(model, b.rows_at(forced[:, 0], forced[:, 1], forced[:, 2]))
    if k == 2:
        th, pd = np.meshgrid(np.deg2rad(RETRO_TH_DEG), geo.PD_GRID, indexing="ij")
        near = np.stack([th.ravel(), np.full(th.size, td), pd.ravel()], axis=1)
        qn = b.rows_at(near[:, 0], near[:, 1], near[:, 2])
        j = greedy_rows(model, qn, np.arange(near.shape[0]), 1,
                        accept=lambda r: _mounts(np.concatenate([forced, near[r]]), rig))
        forced = np.concatenate([forced, near[j]])
        model = _read(model, qn[j])
    rows = greedy_rows(model, b.Q, candidate_rows(rig, b.valid), n - k,
                       accept=lambda r: _mounts(np.concatenate([forced, rows_to_cells(r)]), rig))
    cells = np.concatenate([forced, rows_to_cells(rows)])
    placement = place_pairs(cells, rig, ph_step_deg=1.0, seed=0)
    return np.asarray(placement.cells), np.asarray(placement.ph_lab)


def retro_cached(b: Basis, importance: np.ndarray, k: int, td_deg: float
                 ) -> tuple[np.ndarray, np.ndarray]:
    """:func:`retro_design`, cached by the default design's key plus the study's source."""
    rig = RigConstraints()
    study = hashlib.sha256((inspect.getsource(retro_design) + inspect.getsource(_read)
                            + inspect.getsource(_mounts) + repr(RETRO_TH_DEG)).encode())
    key = (design_key(b, 0.5, importance, 0, rig) + f"-retro{k}-td{td_deg:g}-"
           + study.hexdigest()[:16])
    path = bu.CACHE / f"flipdesign-{hashlib.sha256(key.encode()).hexdigest()[:16]}.npz"
    if path.is_file():
        with np.load(path) as z:
            return z["cells"], z["ph_lab"]
    cells, ph = retro_design(b, importance, k, td_deg)
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez(path, cells=cells, ph_lab=ph)
    return cells, ph


#: Per-view HDR-FLIP of the last scan scored (``bu.flip_of`` is wrapped to record it).
LAST_VIEWS: dict[str, list[float]] = {"views": []}


def _flip_recording(table: Any, m: bu.Material) -> float:
    """``bu.flip_of`` that also keeps the per-view values in :data:`LAST_VIEWS`."""
    from gonio.brdf.pictures import appearance

    res = appearance.standard_flip(bu.truth_images(m), appearance.render_appearance(table))
    LAST_VIEWS["views"] = list(res.per_image)
    return float(res.mean)


def setting_name(w: float | None, k: int | None, eps: float | None = None) -> str:
    """Row-name part of a basis setting: ``w=W K=K`` (the defaults filled in), with
    `` eps=E`` when the remap constant is given (the eps study)."""
    w = MEASURED_WEIGHT if w is None else w
    k = DEFAULT_COMPONENTS if k is None else k
    return f"w={w:g} K={k}" + ("" if eps is None else f" eps={eps:g}")


def eps_synthetic_path(eps: float, n_components: int) -> Path:
    """Cache file of :func:`eps_synthetic`: in the bench's cache, keyed by ``eps``, K and the
    synthetic library's content (``library_key``), so a changed library builds again."""
    from gonio.brdf.materials import library

    return (bu.CACHE / "eps-basis"
            / f"synthetic-K{n_components}-eps{eps:g}-{library.library_key()[:16]}.npz")


def eps_synthetic(eps: float, n_components: int) -> Basis:
    """The synthetic basis of the default library, remapped with ``eps`` (the eps study).

    ``build_basis(default_library(), K, eps=eps)``, the recipe of
    :func:`~gonio.brdf.reconstruction.basis.synthetic_basis` with another remap constant;
    built once per ``(eps, K)`` (about a minute) and cached by :func:`eps_synthetic_path`.
    """
    from gonio.brdf.materials import library

    path = eps_synthetic_path(eps, n_components)
    if path.is_file():
        try:
            return Basis.load(path)
        except BasisError:
            pass  # a damaged cache entry is built again below
    tables = library.default_library()
    basis = build_basis(tables, min(n_components, sum(t.n_channels * geo.N_PH for t in tables)),
                        eps=eps)
    path.parent.mkdir(parents=True, exist_ok=True)
    basis.save(path)
    return basis


def eps_default_basis(eps: float | None, k: int | None, exclude: tuple[str, ...] = (),
                      measured_weight: float | None = None) -> Basis:
    """:func:`~gonio.brdf.reconstruction.basis.default_basis` with the remap constant ``eps``.

    ``None`` or the product's :data:`~gonio.brdf.reconstruction.basis.EPS` is the default basis
    itself (so today's row is today's basis, shipped synthetic part included). Any other
    ``eps``: :func:`eps_synthetic` at ``K + 32`` components, the shipped measured tables but
    ``exclude`` (and the user library's, as the default) folded in with ``fold_in`` at the
    weight, truncated to K; cached next to it, keyed by everything that goes in.
    """
    from gonio.brdf.materials import measured

    if eps is None or eps == EPS:
        return default_basis(k, exclude=exclude, measured_weight=measured_weight)
    k = DEFAULT_COMPONENTS if k is None else int(k)
    weight = MEASURED_WEIGHT if measured_weight is None else float(measured_weight)
    synthetic = eps_synthetic_path(eps, k + _FOLD_EXTRA)
    key = hashlib.sha256("\n".join([
        synthetic.name, measured.measured_digest(), measured.user_library_digest(),
        repr(weight), ",".join(sorted(exclude)), inspect.getsource(eps_default_basis),
    ]).encode()).hexdigest()[:16]
    path = synthetic.parent / f"default-K{k}-eps{eps:g}-{key}.npz"
    if path.is_file():
        try:
            return Basis.load(path)
        except BasisError:
            pass
    base = eps_synthetic(eps, k + _FOLD_EXTRA)
    basis = fold_in(base, measured.measured_tables(exclude) + measured.user_tables(), weight,
                    min(k, base.K))
    basis = Basis(basis.Q, basis.S, basis.f_med, basis.mu, basis.valid, basis.eps,
                  basis.materials, {**basis.provenance, "default_key": key,
                                    "asymmetric_library": False}, basis.ph_prior,
                  basis.local_means, basis.local_names)
    path.parent.mkdir(parents=True, exist_ok=True)
    basis.save(path)
    return basis


def render_row_weight(strength: float) -> np.ndarray:
    """(N_ROWS,) weight ``d = (1 - A) + A c / mean(c)`` of every grid row (the render-weighted
    basis study, module notes): ``c`` the standard renderings' pixel counts
    (:func:`~gonio.brdf.pictures.appearance.render_importance`, ``ph`` summed), the mean taken
    over the valid rows, so ``d`` averages 1 there; invalid rows get 1 (they hold no data).

    Raises
    ------
    ValueError
        For ``A`` outside ``[0, 1)`` (at 1 the cells no rendering looks at would get no
        weight, and a weighted PCA could not place them).
    """
    if not 0 <= strength < 1:
        raise ValueError(f"a render-basis strength must be in [0, 1), got {strength:g}")
    c = np.asarray(render_importance(), dtype=float).ravel()
    valid = geo.valid_mask().ravel()
    d = np.ones(geo.N_ROWS)
    d[valid] = (1.0 - strength) + strength * c[valid] / c[valid].mean()
    return d


class _RowScaled:
    """Within the block, :mod:`~gonio.brdf.reconstruction.basis` learns with its valid rows
    scaled by ``s = sqrt(d)``: ``build_basis``' randomized SVD sees ``s Y`` (the centred,
    remapped matrix, scaled in place, so its coefficients are the weighted least-squares
    ones) and ``fold_in``'s remap returns ``s X``. Both are linear in the rows, so a basis
    learned inside is the weighted PCA's in scaled coordinates (``Q``, ``mu`` times ``s``);
    :func:`_unscaled` takes it back. A bench prototype of a row weight the product's
    builders do not have (wiring it would be an argument of ``build_basis`` and ``fold_in``).
    """

    def __init__(self, d: np.ndarray) -> None:
        self.s = np.sqrt(np.asarray(d, dtype=float))
        self.rows = np.flatnonzero(geo.valid_mask().ravel())

    def __enter__(self) -> _RowScaled:
        from gonio.brdf.reconstruction import basis as basis_mod

        self.mod = basis_mod
        self.svd, self.remap = basis_mod._randomized_svd, basis_mod.remap
        s_rows = self.s[self.rows]

        def svd(Y: np.ndarray, *a: Any) -> Any:
            Y *= s_rows[:, None].astype(np.float32)
            return self.svd(Y, *a)

        def remap(values: Any, f_med: Any, w: Any, eps: float = EPS) -> np.ndarray:
            x = self.remap(values, f_med, w, eps)
            return x * s_rows if x.shape[-1] == s_rows.size else x

        basis_mod._randomized_svd, basis_mod.remap = svd, remap  # type: ignore[assignment]
        return self

    def __exit__(self, *exc: object) -> None:
        self.mod._randomized_svd, self.mod.remap = self.svd, self.remap  # type: ignore[assignment]

    def scaled(self, b: Basis) -> Basis:
        """``b`` in scaled coordinates (``Q``, ``mu`` times ``s``): what ``fold_in`` reads."""
        return replace(b, Q=b.Q * self.s[:, None], mu=b.mu * self.s)

    def unscaled(self, b: Basis, strength: float, *, mu_scaled: bool = True) -> Basis:
        """``b`` learned in scaled coordinates, taken back: ``Q`` over ``s``, and ``mu`` when
        it was learned scaled (``fold_in`` of a :meth:`scaled` base; ``build_basis`` takes
        its row means before the SVD, unscaled: ``mu_scaled=False``)."""
        return replace(b, Q=b.Q / self.s[:, None], mu=b.mu / self.s if mu_scaled else b.mu,
                       provenance={**b.provenance, "render_strength": float(strength)})


def _render_code() -> str:
    """Digest of the study's own source (a change builds its bases again)."""
    src = "".join(inspect.getsource(f) for f in (render_row_weight, _RowScaled,
                                                  render_synthetic, render_default_basis))
    return hashlib.sha256(src.encode()).hexdigest()[:12]


def render_synthetic(strength: float, n_components: int) -> Basis:
    """The synthetic library's basis learned with the rows weighed by
    :func:`render_row_weight` (``build_basis(default_library(), K)`` otherwise); built once per
    ``(A, K)`` and cached in the bench's cache, keyed by them, the library and the study's
    source."""
    from gonio.brdf.materials import library

    path = (bu.CACHE / "render-basis" / f"synthetic-K{n_components}-A{strength:g}-"
            f"{library.library_key()[:16]}-{_render_code()}.npz")
    if path.is_file():
        try:
            return Basis.load(path)
        except BasisError:
            pass
    tables = library.default_library()
    scale = _RowScaled(render_row_weight(strength))
    t0 = time.perf_counter()
    with scale:
        b = build_basis(tables, n_components)
    b = scale.unscaled(b, strength, mu_scaled=False)
    print(f"  render-weighted synthetic basis A={strength:g} K={n_components}: "
          f"{time.perf_counter() - t0:.1f} s", flush=True)
    path.parent.mkdir(parents=True, exist_ok=True)
    b.save(path)
    return b


def render_default_basis(strength: float, exclude: tuple[str, ...] = ()) -> Basis:
    """The default basis (K = 64, weight 1), its synthetic part and the fold-in of the
    shipped measured tables but ``exclude`` weighted by :func:`render_row_weight`; cached."""
    from gonio.brdf.materials import measured

    k = DEFAULT_COMPONENTS
    key = hashlib.sha256("\n".join([
        measured.measured_digest(), measured.user_library_digest(), repr(MEASURED_WEIGHT),
        ",".join(sorted(exclude)), _render_code()]).encode()).hexdigest()[:16]
    base = render_synthetic(strength, k + _FOLD_EXTRA)
    path = bu.CACHE / "render-basis" / f"default-K{k}-A{strength:g}-{key}.npz"
    if path.is_file():
        try:
            return Basis.load(path)
        except BasisError:
            pass
    scale = _RowScaled(render_row_weight(strength))
    with scale:
        b = fold_in(scale.scaled(base), measured.measured_tables(exclude)
                    + measured.user_tables(), MEASURED_WEIGHT, k)
    b = scale.unscaled(b, strength)
    path.parent.mkdir(parents=True, exist_ok=True)
    b.save(path)
    return b


def weighted_ceiling(b: Basis, truth: Any, d: np.ndarray) -> Any:
    """``bu.ceiling`` with the rows weighed by ``d``: the least-squares fit of every slice of
    ``truth`` on ``b`` minimising ``sum_i d_i (remapped error)_i^2``."""
    rows = np.flatnonzero(b.valid)
    x = np.asarray(truth.values, dtype=float).reshape(3, geo.N_PH, geo.N_ROWS)[:, :, rows]
    w = row_weight(b.eps)[rows]
    y = np.nan_to_num(remap(x, b.f_med[rows], w, b.eps), nan=0.0) - b.mu[rows]
    s = np.sqrt(d[rows])
    coef = np.linalg.lstsq(b.Q[rows] * s[:, None], (y.reshape(-1, rows.size) * s).T,
                           rcond=None)[0]
    coef = coef.T.reshape(3, geo.N_PH, b.K).transpose(0, 2, 1)
    return BRDFTable.trusted(expand_table(b, coef), ("R", "G", "B"), "ceiling")


def evaluate_render_basis(mats: list[bu.Material], strengths: list[float], label: str,
                          limits: bool, save: str | None) -> None:
    """The render-weighted basis study (module notes): per material, today's scan and, per
    strength ``A``, the scan on the render-weighted basis with its own pairs and with today's;
    with ``limits`` the ceilings. Prints ``log_rmse`` / HDR-FLIP per material and the means,
    and how many of each row's pairs lie at ``td`` 15-45 degrees (where the renderings look)."""
    importance = render_importance()
    weights = {a: render_row_weight(a) for a in strengths}
    rows: dict[str, dict[str, bu.Score]] = {}
    in_band: dict[str, list[int]] = {}
    flip_before = bu.flip_of
    bu.flip_of = _flip_recording  # type: ignore[assignment]
    t0 = time.perf_counter()

    def band(cells: np.ndarray) -> int:
        td = np.rad2deg(np.asarray(cells)[:, 1])
        return int(np.sum((td >= 15 - 1e-6) & (td <= 45 + 1e-6)))

    for m in mats:
        seed = 100 + int(hashlib.sha256(m.name.encode()).hexdigest()[:6], 16) % 1000
        b0 = default_basis(exclude=m.exclude)
        c0, ph0 = design(b0, 0.5, importance)
        rows.setdefault("today", {})[m.name] = bu.run_scan(b0, m, c0, ph0, 8, seed, "joint")
        in_band.setdefault("today", []).append(band(c0))
        ceilings = [("ceiling today", bu.ceiling(b0, m.truth))] if limits else []
        for a in strengths:
            ba = render_default_basis(a, tuple(m.exclude))
            ca, pha = design(ba, 0.5, importance)
            rows.setdefault(f"rw={a:g}", {})[m.name] = bu.run_scan(ba, m, ca, pha, 8, seed,
                                                                   "joint")
            in_band.setdefault(f"rw={a:g}", []).append(band(ca))
            rows.setdefault(f"rw={a:g}, today's pairs", {})[m.name] = bu.run_scan(
                ba, m, c0, ph0, 8, seed, "joint")
            in_band.setdefault(f"rw={a:g}, today's pairs", []).append(band(c0))
            if limits:
                ceilings += [(f"ceiling rw={a:g}", weighted_ceiling(ba, m.truth, weights[a])),
                             (f"ceiling today's basis, projection {a:g}",
                              weighted_ceiling(b0, m.truth, weights[a]))]
        if limits:
            ceilings.append(("grid limit", m.truth))
        for row, table in ceilings:
            rows.setdefault(row, {})[m.name] = bu.score(table, m.truth, m=m)
        print(f"  {m.name} ({time.perf_counter() - t0:.0f} s)", flush=True)
    bu.flip_of = flip_before  # type: ignore[assignment]
    order = list(rows)
    if save:
        Path(save).write_text(json.dumps(
            {r: {m: {"kind": next(x.kind for x in mats if x.name == m),
                     "log_rmse": s.log_rmse, "flip": s.flip} for m, s in per.items()}
             for r, per in rows.items()}, indent=1))
        print(f"unrounded scores written to {save}")
    print_material_table(label, rows, mats, order)
    print("\nunrounded means (log_rmse measured, mitsuba; HDR-FLIP all):")
    for r in order:
        ms = [rows[r][m.name] for m in mats if m.kind == "measured"]
        an = [rows[r][m.name] for m in mats if m.kind == "aniso"]
        print(f"  {r}: {np.mean([s.log_rmse for s in ms]) if ms else float('nan'):.5f}, "
              f"{np.mean([s.log_rmse for s in an]) if an else float('nan'):.5f}; "
              f"{np.mean([rows[r][m.name].flip for m in mats]):.4f}")
    print("\nmean pairs at td 15-45 deg (of 10):")
    for r, counts in in_band.items():
        print(f"  {r}: {np.mean(counts):.1f}")


def print_material_table(label: str, rows: dict[str, Any], mats: Any, order: list[str]) -> None:
    """The per-material table (``log_rmse / HDR-FLIP`` per row) and its mean rows."""
    print(f"\n{label}: log_rmse / HDR-FLIP per material (lower is better)")
    print("| material | " + " | ".join(order) + " |")
    print("|---" * (1 + len(order)) + "|")
    for m in mats:
        print(f"| {m.name} | " + " | ".join(
            f"{rows[r][m.name].log_rmse:.4f} / {rows[r][m.name].flip:.3f}" for r in order) + " |")
    print_mean_rows(rows, mats, order)


def print_mean_rows(rows: dict[str, dict[str, bu.Score]], mats: list[bu.Material],
                    order: list[str]) -> None:
    """The markdown rows of mean ``log_rmse`` / HDR-FLIP per kind of material and over all,
    one column per row name in ``order`` (the per-material table's closing rows)."""
    groups = [(f"mean {kind}", [m for m in mats if m.kind == kind])
              for kind in ("measured", "aniso")] + [("mean all", mats)]
    for label, ks in groups:
        if ks:
            print(f"| **{label} ({len(ks)})** | " + " | ".join(
                f"**{np.mean([rows[r][m.name].log_rmse for m in ks]):.4f} / "
                f"{np.mean([rows[r][m.name].flip for m in ks]):.3f}**" for r in order) + " |")


def best_preset_wins(rows: dict[str, dict[str, bu.Score]], mats: list[bu.Material], row: str,
                     presets: list[str]) -> tuple[int, int]:
    """On how many of ``mats`` row ``row`` beats the best of ``presets`` (row names) by
    ``log_rmse`` and by HDR-FLIP, each material's best preset taken per metric."""
    g = rows[row]
    wl = sum(g[m.name].log_rmse < min(rows[p][m.name].log_rmse for p in presets) for m in mats)
    wf = sum(g[m.name].flip < min(rows[p][m.name].flip for p in presets) for m in mats)
    return int(wl), int(wf)


def evaluate(mats: list[bu.Material], mixes: list[float], label: str,
             seeds: tuple[int, ...] = (0,), retro: tuple[tuple[int, float], ...] = (),
             presets_on: bool = True, save: str | None = None, limits: bool = False,
             retro_add: tuple[float, ...] = (),
             settings: tuple[tuple[Any, ...], ...] = ((None, None),),
             design_setting: tuple[float, int] | None = None) -> None:
    """Per material and in the mean: log_rmse / HDR-FLIP of every mix (each design seed) and
    every preset (not with several seeds: those compare designs, not presets).

    ``settings`` holds the bases' ``(measured_weight, n_components)`` or
    ``(measured_weight, n_components, eps)`` (None: the default's; ``eps`` the remap
    constant, :func:`eps_default_basis`); with more than one, or any given, every mix row and
    the basis ceiling are repeated per setting, named by it (the basis-settings and eps
    studies, module notes). The retro rows and the
    presets read the first setting's basis. ``design_setting`` (a diagnostic): every setting
    reads the pairs designed on that setting's basis instead of its own, so the rows differ
    by the fit's basis alone."""
    importance = render_importance()
    presets = ({p: get_preset(p).cells() for p in preset_names()}
               if seeds == (0,) and presets_on else {})
    rows: dict[str, dict[str, bu.Score]] = {}
    views: dict[str, dict[str, list[float]]] = {}
    flip_before = bu.flip_of
    bu.flip_of = _flip_recording  # type: ignore[assignment]
    t0 = time.perf_counter()
    named = any(x is not None for st in settings for x in st)
    triples = [(st[0], st[1], st[2] if len(st) > 2 else None) for st in settings]
    for m in mats:
        seed = 100 + int(hashlib.sha256(m.name.encode()).hexdigest()[:6], 16) % 1000
        bases = []
        db = (None if design_setting is None else
              default_basis(design_setting[1], exclude=m.exclude,
                            measured_weight=design_setting[0]))
        for w, k, eps in triples:
            bs = eps_default_basis(eps, k, exclude=m.exclude, measured_weight=w)
            tag = f" {setting_name(w, k, eps)}" if named else ""
            if db is not None:
                tag += f" (pairs of {setting_name(*design_setting)})"
            bases.append((tag, bs))
            for a in mixes:
                for ds in seeds:
                    cells, ph = design(bs if db is None else db, a, importance, ds)
                    row = f"gonio a={a:g}" + (f" seed {ds}" if ds else "") + tag
                    rows.setdefault(row, {})[m.name] = bu.run_scan(bs, m, cells, ph, 8, seed,
                                                                   "joint")
                    views.setdefault(row, {})[m.name] = LAST_VIEWS["views"]
        b = bases[0][1]
        for k, td in retro:
            row = f"retro {k} td={td:g}"
            try:
                cells, ph = retro_cached(b, importance, k, td)
            except (FeasibilityError, DesignError) as exc:  # greedy_rows: DesignError
                print(f"  {row}: does not mount ({exc})", flush=True)
                continue
            if m is mats[0]:
                print(f"  {row} pairs (th, td, pd deg): "
                      + " ".join(f"({c[0]:.0f},{c[1]:g},{c[2]:.0f})" for c in np.rad2deg(cells)),
                      flush=True)
            rows.setdefault(row, {})[m.name] = bu.run_scan(b, m, cells, ph, 8, seed, "joint")
            views.setdefault(row, {})[m.name] = LAST_VIEWS["views"]
        for td in retro_add:  # diagnostic: the default's ten pairs plus (0, td, 0) as an 11th
            row = f"a=0.5 + (0,{td:g},0)"
            dc, _dph = design(b, 0.5, importance)
            cells = np.concatenate([dc, [[0.0, np.deg2rad(td), 0.0]]])
            try:
                ph = place_pairs(cells, RigConstraints(), ph_step_deg=1.0, seed=0).ph_lab
            except FeasibilityError as exc:
                print(f"  {row}: does not mount ({exc})", flush=True)
                continue
            rows.setdefault(row, {})[m.name] = bu.run_scan(b, m, cells, ph, 8, seed, "joint")
            views.setdefault(row, {})[m.name] = LAST_VIEWS["views"]
        for p, (pc, pph) in presets.items():
            rows.setdefault(p, {})[m.name] = bu.run_scan(b, m, pc, pph, 8, seed, "joint")
            views.setdefault(p, {})[m.name] = LAST_VIEWS["views"]
        if limits:  # what no design reaches: each basis' best fit, the truth on the grid
            for row, table in ([(f"basis ceiling{tag}", bu.ceiling(bs, m.truth))
                                for tag, bs in bases] + [("grid limit", m.truth)]):
                rows.setdefault(row, {})[m.name] = bu.score(table, m.truth, m=m)
                views.setdefault(row, {})[m.name] = LAST_VIEWS["views"]
        print(f"  {m.name} ({time.perf_counter() - t0:.0f} s)", flush=True)
    bu.flip_of = flip_before  # type: ignore[assignment]
    order = list(rows)
    if save:
        Path(save).write_text(json.dumps(
            {r: {m: {"kind": next(x.kind for x in mats if x.name == m),
                     "log_rmse": s.log_rmse, "flip": s.flip,
                     "views": views.get(r, {}).get(m, [])} for m, s in per.items()}
             for r, per in rows.items()}, indent=1))
        print(f"unrounded scores written to {save}")
    print_material_table(label, rows, mats, order)
    print("\nmean HDR-FLIP per standard view (lights 20, 55, 55, 70 deg from the view):")
    for kind in ("measured", "aniso"):
        ks = [m for m in mats if m.kind == kind]
        for r in order:
            if ks and all(m.name in views.get(r, {}) for m in ks):
                v = np.mean([views[r][m.name] for m in ks], axis=0)
                print(f"  {kind} ({len(ks)}) {r}: [" + " ".join(f"{x:.3f}" for x in v) + "]")
    if len(seeds) > 1:
        print("\nmean over the design seeds (log_rmse / HDR-FLIP):")
        for a in mixes:
            for kind in ("measured", "aniso"):
                ks = [m for m in mats if m.kind == kind]
                rs = [r for r in order if r == f"gonio a={a:g}" or
                      r.startswith(f"gonio a={a:g} seed")]
                if ks:
                    print(f"  a={a:g} {kind} ({len(ks)}): "
                          f"{np.mean([rows[r][m.name].log_rmse for r in rs for m in ks]):.4f}"
                          f" / {np.mean([rows[r][m.name].flip for r in rs for m in ks]):.3f}")
    if not presets:
        return
    print("\nwins against the best preset per material (log_rmse; HDR-FLIP), of "
          f"{len(mats)}:")
    for r in order:
        if r in presets or r.startswith("basis ceiling") or r == "grid limit":
            continue
        wl, wf = best_preset_wins(rows, mats, r, list(presets))
        print(f"  {r}: log_rmse {wl}, HDR-FLIP {wf}")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("stage", choices=["choose", "test", "fresh", "fresh2", "fresh3"])
    ap.add_argument("--mix", type=float, nargs="+", default=[0.0, 0.25, 0.5, 0.75, 1.0],
                    help="cell_mix values to compare (test: the chosen one; 0 is added)")
    ap.add_argument("--only", nargs="*", default=None, help="material names (exploring)")
    ap.add_argument("--seeds", type=int, nargs="+", default=[0],
                    help="design seeds (the greedy's first-pair rank) to average over; with "
                         "more than one, no preset rows (design-to-design spread)")
    ap.add_argument("--retro", type=int, nargs="*", default=[], choices=[1, 2],
                    help="forced near-retro specular pairs (retro-pair study, "
                         "docs/notes/2026-11-27-retro-pair.md): each K runs with each --retro-td")
    ap.add_argument("--retro-td", type=float, nargs="+", default=[10.0],
                    help="td (degrees) of the forced pairs")
    ap.add_argument("--no-presets", action="store_true", help="leave out the preset rows")
    ap.add_argument("--retro-add", type=float, nargs="*", default=[],
                    help="diagnostic rows: the default's ten pairs plus (0, TD, 0) as an 11th")
    ap.add_argument("--limits", action="store_true",
                    help="add the basis ceiling and the grid limit rows (no scan)")
    ap.add_argument("--measured-weight", type=float, nargs="+", default=None,
                    help="basis-settings study: the default basis' measured weight(s) W "
                         "(default: MEASURED_WEIGHT); every (W, K) is its own rows")
    ap.add_argument("--components", type=int, nargs="+", default=None,
                    help="basis-settings study: K of the default basis (default: "
                         "DEFAULT_COMPONENTS); K = 96 builds the 128-component synthetic "
                         "basis once")
    ap.add_argument("--eps", type=float, nargs="+", default=None,
                    help="eps study: the basis remap constant(s) (default: the product's "
                         "EPS); every (W, K, eps) is its own rows; another eps builds its "
                         "synthetic basis once (K + 32 components) in the bench cache")
    ap.add_argument("--design-setting", type=float, nargs=2, default=None, metavar=("W", "K"),
                    help="basis-settings study, a diagnostic: every setting reads the pairs "
                         "designed on the basis of weight W and K components")
    ap.add_argument("--render-basis", type=float, nargs="+", default=None, metavar="A",
                    help="render-weighted basis study: the strengths A in [0, 1) of the "
                         "basis' row weight (1 - A) + A c / mean(c); runs that study only")
    ap.add_argument("--save", default=None, help="write the unrounded scores to this JSON file")
    args = ap.parse_args(argv)
    study = (args.measured_weight is not None or args.components is not None
             or args.eps is not None)
    if any(w < 0 for w in args.measured_weight or []):
        ap.error("--measured-weight: give weights >= 0 (how many synthetic materials one "
                 "measured material counts as)")
    if any(not 1 <= k <= 128 for k in args.components or []):
        ap.error("--components: give K between 1 and 128 (the synthetic basis is built with "
                 "K + 32 components)")
    if any(not 0 < e < 1 for e in args.eps or []):
        ap.error("--eps: give remap constants between 0 and 1 exclusive (the product's is "
                 f"{EPS:g})")
    print(f"$ {' '.join(['python', *sys.argv])}")
    imp = render_importance()
    print(f"render importance: {imp.sum():.0f} pixel lookups on {(imp > 0).sum()} nodes, "
          f"{imp[geo.valid_mask()].sum() / imp.sum():.1%} on valid cells")
    # The study compares bases at the given design mix only; otherwise 0 is always a row.
    mixes = sorted(set(args.mix)) if study else sorted(set([0.0, *args.mix]))
    settings: tuple[tuple[float | None, int | None, float | None], ...] = tuple(
        (w, k, e) for w in (args.measured_weight or [None]) for k in (args.components or [None])
        for e in (args.eps or [None])
    ) if study else ((None, None, None),)
    # Built only for the stage asked for: a set's truth tables are made when it first runs.
    make = {"choose": lambda: ("choice set", material_sets()[0]),
            "test": lambda: ("test set", material_sets()[1]),
            "fresh": lambda: ("fresh set", bu.aniso_materials(FRESH_FLIP)),
            "fresh2": lambda: ("second fresh set", bu.aniso_materials(FRESH2_FLIP)),
            "fresh3": lambda: ("third fresh set", bu.aniso_materials(FRESH3_FLIP))}
    if any(not 0 <= a < 1 for a in args.render_basis or []):
        ap.error("--render-basis: give strengths A with 0 <= A < 1 (at 1 the cells no "
                 "rendering looks at would get no weight)")
    for label, mats in [make[args.stage]()]:
        if args.only:
            mats = [m for m in mats if m.name in args.only]
        if args.render_basis is not None:
            evaluate_render_basis(mats, sorted(set(args.render_basis)), label, args.limits,
                                  args.save)
            continue
        evaluate(mats, mixes, label, tuple(args.seeds),
                 tuple((k, td) for k in args.retro for td in args.retro_td),
                 not args.no_presets, args.save, args.limits, tuple(args.retro_add),
                 settings, None if args.design_setting is None
                 else (args.design_setting[0], int(args.design_setting[1])))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
