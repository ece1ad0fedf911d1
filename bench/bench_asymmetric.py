"""Benchmark: specimens without twofold symmetry from an independent renderer (issue 25).

Run from the project root (needs mitsuba: ``pip install 'gonio[rgl]'``)::

    nice -n 5 .venv/bin/python bench/bench_asymmetric.py [--seeds 5]

Specimens
---------
* **Asymmetric**: mitsuba 3 (``scalar_rgb``) ``normalmap`` BSDFs with a constant normal map
  (every facet's normal tilted 10-30 deg one way) over a rough conductor or a rough plastic,
  several roughnesses, each turned by an arbitrary holder angle. Readings are mitsuba at the
  exact pair directions with 1 % relative noise; the truth is mitsuba on gonio's grid (as in
  ``bench_unseen.py``, whose helpers this uses).
* **Symmetric** (for the symmetry test's false alarms): ``bench_unseen.py``'s six anisotropic
  mitsuba specimens and the untilted versions of the asymmetric ones, each scanned with
  ``--seeds`` noise seeds.

Rows per asymmetric specimen (10 pairs designed by the joint fit's expected error on the basis
of the row, ``r`` uniform stage angles):

* ``half``: the default, the default basis, pairs designed for and angles over half a turn, r = 8;
* ``full``: the default basis, pairs designed for a full turn, 8 angles over 360 deg;
* ``asym full r``: the basis trained with the families without twofold symmetry
  (``default_basis(asymmetric=True)``), pairs designed for a full turn, r = 8 and 12 over 360
  deg (80 and 120 readings);
* ``asym full r=12, default pairs``: the same fit and 12 angles, on the pairs the default design
  makes (the default basis over half a turn: the pairs a scan has when its arc test calls the
  specimen asymmetric; docs/notes/2026-11-28-asymmetric-metals.md);
* the basis ceilings (every cell known) of both bases;
* the twofold test (:func:`gonio.brdf.reconstruction.symmetry.twofold_test`, 1 % false alarm)
  on the full-turn r = 8 scan (4 opposite pairs): overall p-value and verdict, pairs flagged.

The issue's goals: asymmetric mean ``log_rmse <= 0.06`` within 120 readings at 10 pairs; the
test calls at most 1 in 20 symmetric scans asymmetric.

The auto-arc path (``--auto``, what a scan with ``arc = "auto"`` does, docs/science.md 7.4): the
rig's 10 pairs (designed for the default basis over half a turn, as the default design), the first
round of :func:`gonio.plans.arc.first_round_angles` (``R`` angles over half a turn plus one
opposite; ``--layout`` compares other first rounds, ``LAYOUTS``), the engine's test
(:func:`gonio.plans.arc.arc_test`, on the readings scaled per pair as the engine's raw counts are);
symmetric, the joint fit with the default basis on those angles; asymmetric, the fill round
(:func:`gonio.plans.arc.fill_angles`: ``2R`` angles over the full turn in all) and the fit with the
basis the verdict chooses: the default one (before issue 25's switch) or the asymmetric one
(after). Rows for ``R`` = 6 (120 readings when asymmetric) and 8 (160), on the asymmetric
specimens, and on the symmetric ones (their readings and error beside today's half-turn scan of 8
angles, 80 readings). ``--set fresh`` runs the same tables on ``ASYM_FRESH`` and its untilted twins
(the held-out set of the layout choice).

The tilt fit (``--tilt choice|fresh|symmetric``, docs/science.md 7.4): on the auto-arc path's
readings (``--rotations`` R, 6 by default: 120 readings when asymmetric), today's fit (the basis
the verdict chooses) against :func:`gonio.brdf.reconstruction.tilt.fit_tilt` with the default
basis on the same readings, the lean it finds against the truth's, both fits' leave-one-pair-out
errors and the tilt search's CPU time. ``choice``: the 8 specimens above, where its settings
were chosen; ``fresh``: :data:`FRESH`, written before its single run; ``symmetric``:
``bench_unseen.py``'s six anisotropic specimens read over a full turn (2R angles), plain joint
fit against the tilt fit; ``fresh2``: :data:`FRESH2`, written and committed before any run,
for the selection rule's single test. The ``rule`` column: the selection rule
(:func:`gonio.brdf.reconstruction.tilt.tilt_decision`, chosen on the choice set): the tilt
fit when it lowers the leave-one-pair-out error of at least 70 % of the pairs against the
fit the scan gets without it, else that fit.

The disagreement round (``--disagree choice|fresh|fresh2|fresh3|symmetric``, docs/science.md
7.4, :mod:`gonio.brdf.reconstruction.disagree`): a first pass on the auto-arc path with
``--first-rotations`` R (``20 R`` readings when asymmetric), today's fit and the tilt fit on
it, a round of stage angles placed where their predictions disagree most (``--score``), read,
and the fit that predicted them better refitted on every reading (``--refit``), up to 120
readings; beside today's path and the tilt fit at 120 readings (R = 6). ``fresh3``:
:data:`FRESH3`, written and committed before any run.

The adaptive auto-arc path (``--adaptive SET``, docs/science.md 7.4): the product's default
adaptive plan (:class:`gonio.plans.models.AdaptivePlan`: 4 first angles, the posterior rule,
``min_gain``, at most 16 angles and 6 rounds) with ``arc = "auto"``, its rounds as
:class:`gonio.plans.rounds.ArcRounds` runs them (the first round with one opposite, the test,
the fill round when asymmetric, then :class:`gonio.refinement.PosteriorRefiner` in the arc
chosen) and the fit with the basis the verdict chooses. Two columns: the refinement planned
with the default basis' posterior (``before``: the product until issue 25's refinement basis)
and with the basis finishing reconstructs with (``after``: the asymmetric one once the test
calls the specimen so). ``SET`` is ``choice`` (:data:`ASYM`), ``asym-fresh``
(:data:`ASYM_FRESH`) or ``fresh``..``fresh5``; each with its untilted twins (and for
``choice`` ``bench_unseen.py``'s six anisotropic specimens) as the symmetric specimens,
``--seeds`` noise seeds each, beside a fixed half-turn adaptive plan (today's default arc).

``--tilt`` also prints the two fits **averaged in log** (:func:`log_average`: no choice
between them, so no rule to be fooled by a misplaced lean). ``fresh4``: :data:`FRESH4`,
written and committed before any run, to test the average once.
"""

from __future__ import annotations

import argparse
import hashlib
import sys
import time
from typing import Any

import bench_unseen as bu  # the sibling bench (the script's folder is on sys.path)
import numpy as np

from gonio.brdf.reconstruction.basis import Basis, default_basis
from gonio.brdf.reconstruction.reconstruct import reconstruct
from gonio.brdf.reconstruction.samples import NoiseModel, uniform_stage_angles
from gonio.brdf.reconstruction.symmetry import twofold_test
from gonio.brdf.reconstruction.tilt import fit_tilt
from gonio.brdf.tables import geometry as geo
from gonio.brdf.tables import metrics
from gonio.brdf.tables.table import BRDFTable
from gonio.plans.arc import fill_after, fill_angles, first_round_angles
from gonio.plans.models import AdaptivePlan
from gonio.plans.rounds import RoundRequest, refinement_basis
from gonio.refinement import PosteriorRefiner

MASK = geo.valid_mask()

#: (name, facet tilt deg, tilt azimuth deg, inner mitsuba BSDF, holder angle deg).
ASYM: list[tuple[str, float, float, dict[str, Any], float]] = [
    ("al-r0.10-t15", 15.0, 0.0, {"type": "roughconductor", "material": "Al", "alpha": 0.10},
     23.0),
    ("al-r0.25-t20", 20.0, 40.0, {"type": "roughconductor", "material": "Al", "alpha": 0.25},
     141.0),
    ("au-r0.15-t10", 10.0, 200.0, {"type": "roughconductor", "material": "Au", "alpha": 0.15},
     77.5),
    ("cu-r0.30-t30", 30.0, 110.0, {"type": "roughconductor", "material": "Cu", "alpha": 0.30},
     260.0),
    ("red-plastic-r0.10-t15", 15.0, 300.0,
     {"type": "roughplastic", "alpha": 0.10,
      "diffuse_reflectance": {"type": "rgb", "value": [0.6, 0.08, 0.06]}}, 311.0),
    ("red-plastic-r0.25-t20", 20.0, 15.0,
     {"type": "roughplastic", "alpha": 0.25,
      "diffuse_reflectance": {"type": "rgb", "value": [0.5, 0.05, 0.05]}}, 5.0),
    ("blue-plastic-r0.20-t25", 25.0, 180.0,
     {"type": "roughplastic", "alpha": 0.20,
      "diffuse_reflectance": {"type": "rgb", "value": [0.1, 0.2, 0.55]}}, 199.0),
    ("ag-aniso-t15", 15.0, 90.0, {"type": "roughconductor", "material": "Ag", "alpha_u": 0.08,
                                  "alpha_v": 0.3}, 58.0),
]

#: Fresh asymmetric specimens for the tilt fit's single test (``--tilt fresh``), written
#: down before its first run: other tilts, roughnesses, holder angles, metals and plastics.
#: Nothing was chosen on them.
FRESH: list[tuple[str, float, float, dict[str, Any], float]] = [
    ("fresh-al-r0.18-t12", 12.0, 250.0,
     {"type": "roughconductor", "material": "Al", "alpha": 0.18}, 102.0),
    ("fresh-au-r0.08-t22", 22.0, 330.0,
     {"type": "roughconductor", "material": "Au", "alpha": 0.08}, 17.0),
    ("fresh-cu-r0.12-t8", 8.0, 60.0,
     {"type": "roughconductor", "material": "Cu", "alpha": 0.12}, 215.0),
    ("fresh-ag-r0.20-t26", 26.0, 150.0,
     {"type": "roughconductor", "material": "Ag", "alpha": 0.20}, 289.0),
    ("fresh-cr-aniso-t18", 18.0, 275.0,
     {"type": "roughconductor", "material": "Cr", "alpha_u": 0.12, "alpha_v": 0.25}, 133.0),
    ("fresh-green-plastic-r0.12-t28", 28.0, 95.0,
     {"type": "roughplastic", "alpha": 0.12,
      "diffuse_reflectance": {"type": "rgb", "value": [0.1, 0.45, 0.12]}}, 44.0),
    ("fresh-white-plastic-r0.30-t10", 10.0, 205.0,
     {"type": "roughplastic", "alpha": 0.30,
      "diffuse_reflectance": {"type": "rgb", "value": [0.7, 0.7, 0.65]}}, 166.0),
    ("fresh-yellow-plastic-r0.06-t18", 18.0, 20.0,
     {"type": "roughplastic", "alpha": 0.06,
      "diffuse_reflectance": {"type": "rgb", "value": [0.6, 0.5, 0.05]}}, 321.0),
]


#: A second fresh set for the tilt fit's selection rule (``--tilt fresh2``), written down and
#: committed before any run on it and run once with the rule chosen on the choice set: other
#: metals (Rh, Mo, Ni, Ta), roughnesses, colours, tilts 6-28 deg and holder angles.
FRESH2: list[tuple[str, float, float, dict[str, Any], float]] = [
    ("fresh2-rh-r0.14-t14", 14.0, 120.0,
     {"type": "roughconductor", "material": "Rh", "alpha": 0.14}, 71.0),
    ("fresh2-mo-r0.22-t24", 24.0, 305.0,
     {"type": "roughconductor", "material": "Mo", "alpha": 0.22}, 238.0),
    ("fresh2-ni-r0.09-t9", 9.0, 185.0,
     {"type": "roughconductor", "material": "Ni_palik", "alpha": 0.09}, 12.0),
    ("fresh2-ta-aniso-t20", 20.0, 35.0,
     {"type": "roughconductor", "material": "Ta", "alpha_u": 0.20, "alpha_v": 0.08}, 147.0),
    ("fresh2-cu-r0.20-t16", 16.0, 260.0,
     {"type": "roughconductor", "material": "Cu", "alpha": 0.20}, 299.0),
    ("fresh2-orange-plastic-r0.09-t21", 21.0, 345.0,
     {"type": "roughplastic", "alpha": 0.09,
      "diffuse_reflectance": {"type": "rgb", "value": [0.7, 0.3, 0.05]}}, 84.0),
    ("fresh2-grey-plastic-r0.18-t6", 6.0, 95.0,
     {"type": "roughplastic", "alpha": 0.18,
      "diffuse_reflectance": {"type": "rgb", "value": [0.3, 0.3, 0.3]}}, 201.0),
    ("fresh2-purple-plastic-r0.24-t28", 28.0, 230.0,
     {"type": "roughplastic", "alpha": 0.24,
      "diffuse_reflectance": {"type": "rgb", "value": [0.35, 0.1, 0.45]}}, 330.0),
]


#: A third fresh set for the disagreement round (``--disagree fresh3``), written down and
#: committed before any run on it, made as :data:`FRESH2` is: metals no set used before (Ir,
#: Nb, TiN, anisotropic V, Be), three plastics of new colours, roughnesses 0.07-0.27, tilts
#: 7-30 deg and new holder angles. Nothing was chosen on it.
FRESH3: list[tuple[str, float, float, dict[str, Any], float]] = [
    ("fresh3-ir-r0.16-t18", 18.0, 70.0,
     {"type": "roughconductor", "material": "Ir", "alpha": 0.16}, 118.0),
    ("fresh3-nb-r0.11-t27", 27.0, 210.0,
     {"type": "roughconductor", "material": "Nb", "alpha": 0.11}, 263.0),
    ("fresh3-tin-r0.20-t11", 11.0, 340.0,
     {"type": "roughconductor", "material": "TiN", "alpha": 0.20}, 29.0),
    ("fresh3-v-aniso-t23", 23.0, 160.0,
     {"type": "roughconductor", "material": "V_palik", "alpha_u": 0.10, "alpha_v": 0.22},
     187.0),
    ("fresh3-be-r0.07-t7", 7.0, 25.0,
     {"type": "roughconductor", "material": "Be", "alpha": 0.07}, 312.0),
    ("fresh3-cyan-plastic-r0.13-t30", 30.0, 285.0,
     {"type": "roughplastic", "alpha": 0.13,
      "diffuse_reflectance": {"type": "rgb", "value": [0.05, 0.4, 0.45]}}, 56.0),
    ("fresh3-brown-plastic-r0.27-t13", 13.0, 120.0,
     {"type": "roughplastic", "alpha": 0.27,
      "diffuse_reflectance": {"type": "rgb", "value": [0.35, 0.2, 0.08]}}, 241.0),
    ("fresh3-pink-plastic-r0.07-t24", 24.0, 50.0,
     {"type": "roughplastic", "alpha": 0.07,
      "diffuse_reflectance": {"type": "rgb", "value": [0.7, 0.3, 0.4]}}, 164.0),
]


#: A fourth fresh set for the averaged fit (``--tilt fresh4``: today's fit and the tilt fit
#: averaged in log), written down and committed (2026-11-27) before any run on it, made as
#: :data:`FRESH2` is: two metals no set used before (TiC, VN), three used before (Ag,
#: anisotropic Al, W) at new roughnesses, three plastics of new colours; roughnesses
#: 0.08-0.30, tilts 8-27 deg and new holder angles. Nothing is chosen on it.
FRESH4: list[tuple[str, float, float, dict[str, Any], float]] = [
    ("fresh4-tic-r0.12-t16", 16.0, 150.0,
     {"type": "roughconductor", "material": "TiC", "alpha": 0.12}, 205.0),
    ("fresh4-vn-r0.20-t22", 22.0, 10.0,
     {"type": "roughconductor", "material": "VN", "alpha": 0.20}, 87.0),
    ("fresh4-ag-r0.10-t9", 9.0, 275.0,
     {"type": "roughconductor", "material": "Ag", "alpha": 0.10}, 319.0),
    ("fresh4-al-aniso-t19", 19.0, 65.0,
     {"type": "roughconductor", "material": "Al", "alpha_u": 0.08, "alpha_v": 0.24}, 12.0),
    ("fresh4-w-r0.28-t13", 13.0, 320.0,
     {"type": "roughconductor", "material": "W", "alpha": 0.28}, 140.0),
    ("fresh4-teal-plastic-r0.11-t27", 27.0, 240.0,
     {"type": "roughplastic", "alpha": 0.11,
      "diffuse_reflectance": {"type": "rgb", "value": [0.05, 0.35, 0.3]}}, 262.0),
    ("fresh4-olive-plastic-r0.30-t8", 8.0, 100.0,
     {"type": "roughplastic", "alpha": 0.30,
      "diffuse_reflectance": {"type": "rgb", "value": [0.4, 0.4, 0.1]}}, 33.0),
    ("fresh4-navy-plastic-r0.08-t20", 20.0, 190.0,
     {"type": "roughplastic", "alpha": 0.08,
      "diffuse_reflectance": {"type": "rgb", "value": [0.05, 0.08, 0.35]}}, 171.0),
]


#: A fifth fresh set for the lean-uncertainty study (``bench_leanavg.py --set fresh5``; docs/notes/
#: 2026-11-27-lean-averaging.md), written down and committed (2026-11-27) before any fit on it,
#: made as :data:`FRESH2` is: two metals no set used before (VC, Li), three used before (Au,
#: anisotropic Ni, Ag) at new roughnesses, three plastics of new colours; roughnesses
#: 0.09-0.24, tilts 6-30 deg and new holder angles. Nothing is chosen on it: it is a test set.
FRESH5: list[tuple[str, float, float, dict[str, Any], float]] = [
    ("fresh5-vc-r0.15-t21", 21.0, 115.0,
     {"type": "roughconductor", "material": "VC", "alpha": 0.15}, 308.0),
    ("fresh5-au-r0.11-t14", 14.0, 285.0,
     {"type": "roughconductor", "material": "Au", "alpha": 0.11}, 62.0),
    ("fresh5-ni-aniso-t26", 26.0, 20.0,
     {"type": "roughconductor", "material": "Ni_palik", "alpha_u": 0.09, "alpha_v": 0.20},
     227.0),
    ("fresh5-li-r0.24-t9", 9.0, 170.0,
     {"type": "roughconductor", "material": "Li", "alpha": 0.24}, 14.0),
    ("fresh5-ag-r0.13-t30", 30.0, 235.0,
     {"type": "roughconductor", "material": "Ag", "alpha": 0.13}, 131.0),
    ("fresh5-magenta-plastic-r0.16-t6", 6.0, 300.0,
     {"type": "roughplastic", "alpha": 0.16,
      "diffuse_reflectance": {"type": "rgb", "value": [0.55, 0.08, 0.45]}}, 99.0),
    ("fresh5-lime-plastic-r0.09-t19", 19.0, 65.0,
     {"type": "roughplastic", "alpha": 0.09,
      "diffuse_reflectance": {"type": "rgb", "value": [0.4, 0.6, 0.08]}}, 176.0),
    ("fresh5-sand-plastic-r0.21-t24", 24.0, 140.0,
     {"type": "roughplastic", "alpha": 0.21,
      "diffuse_reflectance": {"type": "rgb", "value": [0.6, 0.5, 0.3]}}, 251.0),
]


#: A fresh set for the auto arc's layout choice (``--set fresh``), written before its first
#: run and run once: other metals, roughnesses, colours, holder angles, and two small tilts
#: (6 and 8 deg) that probe the test's power below the choice set's 10 deg.
ASYM_FRESH: list[tuple[str, float, float, dict[str, Any], float]] = [
    ("cr-r0.12-t12", 12.0, 250.0, {"type": "roughconductor", "material": "Cr", "alpha": 0.12},
     33.0),
    ("w-r0.35-t22", 22.0, 75.0, {"type": "roughconductor", "material": "W", "alpha": 0.35},
     288.0),
    ("au-r0.08-t6", 6.0, 330.0, {"type": "roughconductor", "material": "Au", "alpha": 0.08},
     151.0),
    ("cu-aniso-t18", 18.0, 160.0, {"type": "roughconductor", "material": "Cu", "alpha_u": 0.3,
                                   "alpha_v": 0.07}, 96.0),
    ("green-plastic-r0.15-t8", 8.0, 20.0,
     {"type": "roughplastic", "alpha": 0.15,
      "diffuse_reflectance": {"type": "rgb", "value": [0.08, 0.4, 0.1]}}, 222.0),
    ("white-plastic-r0.30-t28", 28.0, 210.0,
     {"type": "roughplastic", "alpha": 0.30,
      "diffuse_reflectance": {"type": "rgb", "value": [0.8, 0.8, 0.78]}}, 12.0),
    ("yellow-plastic-r0.06-t16", 16.0, 130.0,
     {"type": "roughplastic", "alpha": 0.06,
      "diffuse_reflectance": {"type": "rgb", "value": [0.7, 0.55, 0.05]}}, 345.0),
    ("al-r0.18-t25", 25.0, 285.0, {"type": "roughconductor", "material": "Al", "alpha": 0.18},
     180.0),
]


def normalmap_spec(tilt_deg: float, azimuth_deg: float, inner: dict[str, Any]) -> dict[str, Any]:
    """A mitsuba normalmap BSDF whose every normal leans ``tilt_deg`` toward ``azimuth_deg``."""
    mi = bu._mitsuba()
    t, p = np.deg2rad(tilt_deg), np.deg2rad(azimuth_deg)
    n = np.array([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)])
    rgb = np.ascontiguousarray(np.tile(((n + 1) / 2).astype(np.float32), (2, 2, 1)))
    return {"type": "normalmap", "bsdf": inner,
            "normalmap": {"type": "bitmap", "bitmap": mi.Bitmap(rgb), "raw": True,
                          "filter_type": "nearest"}}


def specimen(name: str, spec: dict[str, Any], holder: float, key: str) -> bu.Material:
    """A mitsuba specimen and its truth table on the grid (cached like bench_unseen's)."""
    s = bu.MitsubaSpecimen(spec, holder)
    th, td, pd = geo.grid_angles()

    def make() -> np.ndarray:
        vals = np.empty((3, geo.N_PH, int(MASK.sum())), dtype=np.float32)
        for k, ph in enumerate(geo.PH_GRID):
            wi, wo = geo.half_diff_to_directions(th[MASK], ph, td[MASK], pd[MASK])
            vals[:, k] = s.eval(wi, wo).T
        return vals

    digest = hashlib.sha256(key.encode()).hexdigest()[:12]
    vals = bu._cached(f"asym-{name}-{digest}", make)
    return bu.Material(name, "aniso", bu._full_table(vals, name), s, ())


def asym_materials(tilted: bool = True,
                   specs: list[tuple[str, float, float, dict[str, Any], float]] | None = None
                   ) -> list[bu.Material]:
    """The asymmetric specimens of ``specs`` (default :data:`ASYM`; :data:`ASYM_FRESH`,
    :data:`FRESH`), or with ``tilted`` False their untilted twins."""
    out = []
    for name, tilt, azimuth, inner, holder in ASYM if specs is None else specs:
        t = tilt if tilted else 0.0
        spec = normalmap_spec(t, azimuth, inner)
        out.append(specimen(name if tilted else f"{name}-untilted", spec, holder,
                            repr((t, azimuth, inner, holder))))
    return out


def design(b: Basis, span: float, n: int = 10) -> tuple[np.ndarray, np.ndarray]:
    bu.CHOOSE["objective"] = "posterior"
    bu.SPAN["design"] = span
    return bu.design(b, n)


def scan(b: Basis, m: bu.Material, cells: np.ndarray, ph: np.ndarray, r: int, span: float,
         seed: int) -> tuple[float, np.ndarray, np.ndarray]:
    """log_rmse of the joint fit on ``r`` uniform angles over ``span`` deg, and the scan."""
    alpha = uniform_stage_angles(r, span=np.deg2rad(span))
    vals = bu.read(m, cells, ph, alpha, seed)
    rec = reconstruct(b, cells, ph, alpha, vals)
    return metrics.log_rmse(rec.table, m.truth), alpha, vals


def _layout_opposites(distinct: int, picks: list[int]
                      ) -> tuple[list[float], list[float]]:
    """``distinct`` uniform angles over half a turn, the opposites of those at ``picks``, and
    the fill round's opposites of the rest."""
    half = [180.0 * k / distinct for k in range(distinct)]
    first = half + [half[k] + 180.0 for k in picks]
    fill = [a + 180.0 for k, a in enumerate(half) if k not in picks]
    return first, fill


#: First-round layouts of the auto arc (``--layout``): each maps ``R`` to (first round, fill
#: round) angles in degrees. ``one``: the product's (R over half a turn plus the first one's
#: opposite, R + 1 angles; :func:`gonio.plans.arc.first_round_angles`); ``two``: the
#: product's when the pairs' planes do not spread, and every auto scan's before this round
#: (plus a second opposite a quarter turn on, R + 2); ``swap``: R - 1 over half a turn
#: plus one opposite (R angles, so a symmetric specimen reads as many as a half-turn plan but
#: sees R - 1 distinct azimuths); ``swap2``: R - 2 plus two opposites a quarter turn apart.
LAYOUTS = {
    "one": lambda r: (first_round_angles(0.0, r, 1), fill_angles(0.0, r, 1)),
    "two": lambda r: (first_round_angles(0.0, r, 2), fill_angles(0.0, r, 2)),
    "swap": lambda r: _layout_opposites(r - 1, [0]),
    "swap2": lambda r: _layout_opposites(r - 2, [0, (r - 2) // 2]),
}


def auto_scan(plain: Basis, asym: Basis, m: bu.Material, cells: np.ndarray, ph: np.ndarray,
              rotations: int, seed: int, layout: str = "one") -> dict[str, Any]:
    """The auto-arc path on one specimen: the verdict, readings and the log_rmse with the
    default basis and (when found asymmetric) with the asymmetric one."""
    from gonio.plans.arc import arc_test

    first, fill = LAYOUTS[layout](rotations)
    vals = bu.read(m, cells, ph, np.deg2rad(first), seed)
    test = arc_test(first, vals, 0.01)
    angles = list(first)
    if not test["symmetric"]:
        vals = np.concatenate([vals, bu.read(m, cells, ph, np.deg2rad(fill), seed + 1)], axis=1)
        angles += fill
    alpha = np.deg2rad(angles)
    out: dict[str, Any] = {"symmetric": bool(test["symmetric"]), "p": test["p_value"],
                           "readings": len(cells) * len(angles)}
    out["default"] = metrics.log_rmse(reconstruct(plain, cells, ph, alpha, vals).table, m.truth)
    out["switched"] = out["default"] if test["symmetric"] else metrics.log_rmse(
        reconstruct(asym, cells, ph, alpha, vals).table, m.truth)
    return out


def auto_rows(plain: Basis, asym: Basis, d_half: tuple[np.ndarray, np.ndarray],
              seeds: int, layout: str = "one", fresh: bool = False) -> None:
    """The auto-arc path's tables (module notes): asymmetric and symmetric specimens
    (``fresh``: ASYM_FRESH and its untilted twins only)."""
    mats = asym_materials(specs=ASYM_FRESH if fresh else None)
    print(f"\nauto arc, first-round layout {layout!r}, the default design's 10 pairs (designed "
          "for half a turn):")
    print("\n| specimen | R | verdict (p) | readings | default basis (before) | "
          "asymmetric basis (after) |")
    print("|---|---|---|---|---|---|")
    means: dict[int, list[tuple[float, float, int]]] = {6: [], 8: []}
    for rotations in (6, 8):
        for i, m in enumerate(mats):
            r = auto_scan(plain, asym, m, *d_half, rotations, 500 + i, layout)
            means[rotations].append((r["default"], r["switched"], r["readings"]))
            verdict = "symmetric" if r["symmetric"] else "NOT symmetric"
            print(f"| {m.name} | {rotations} | {verdict} ({r['p']:.2g}) | {r['readings']} | "
                  f"{r['default']:.4f} | {r['switched']:.4f} |", flush=True)
        a = np.array(means[rotations], dtype=float)
        print(f"| **mean** | {rotations} | | {a[:, 2].mean():.0f} | {a[:, 0].mean():.4f} | "
              f"**{a[:, 1].mean():.4f}** |")
    sym = (asym_materials(tilted=False, specs=ASYM_FRESH) if fresh
           else bu.aniso_materials() + asym_materials(tilted=False))
    print(f"\nsymmetric specimens ({len(sym)}), auto arc R = 8 against today's half turn "
          f"r = 8 (80 readings), {seeds} noise seeds each (mean over seeds):")
    print("\n| specimen | half r=8 | auto R=8 | auto readings | called asymmetric |")
    print("|---|---|---|---|---|")
    rows, alarms, total = [], 0, 0
    for j, m in enumerate(sym):
        half, auto, reads, flagged = [], [], [], 0
        for k in range(seeds):
            seed = 9000 + 37 * j + k
            half.append(scan(plain, m, *d_half, 8, 180.0, seed)[0])
            r = auto_scan(plain, asym, m, *d_half, 8, seed, layout)
            auto.append(r["switched"])
            reads.append(r["readings"])
            flagged += not r["symmetric"]
        alarms, total = alarms + flagged, total + seeds
        rows.append((np.mean(half), np.mean(auto), np.mean(reads)))
        print(f"| {m.name} | {rows[-1][0]:.4f} | {rows[-1][1]:.4f} | {rows[-1][2]:.0f} | "
              f"{flagged} of {seeds} |", flush=True)
    a = np.array(rows)
    print(f"| **mean** | {a[:, 0].mean():.4f} | {a[:, 1].mean():.4f} | {a[:, 2].mean():.0f} | "
          f"{alarms} of {total} |")


def tilt_scan(plain: Basis, asym: Basis, m: bu.Material, cells: np.ndarray, ph: np.ndarray,
              rotations: int, seed: int) -> dict[str, Any]:
    """The auto-arc path (:func:`auto_scan`'s readings) and, on the same readings, the tilt fit
    (:func:`gonio.brdf.reconstruction.tilt.fit_tilt`) with the default basis."""
    from gonio.plans.arc import arc_test, fill_angles, first_round_angles

    first = first_round_angles(0.0, rotations, 1)  # the design's pairs spread
    vals = bu.read(m, cells, ph, np.deg2rad(first), seed)
    test = arc_test(first, vals, 0.01)
    angles = list(first)
    if not test["symmetric"]:
        fill = fill_angles(0.0, rotations, 1)
        vals = np.concatenate([vals, bu.read(m, cells, ph, np.deg2rad(fill), seed + 1)], axis=1)
        angles += fill
    alpha = np.deg2rad(angles)
    today = reconstruct(plain if test["symmetric"] else asym, cells, ph, alpha, vals)
    t0 = time.process_time()
    tf = fit_tilt(plain, cells, ph, alpha, vals, reference=plain if test["symmetric"] else asym)
    cpu = time.process_time() - t0
    average = log_average(today.table, tf.table)
    return {"symmetric": bool(test["symmetric"]), "readings": len(cells) * len(angles),
            "average": metrics.log_rmse(average, m.truth),
            "accepted": tf.accepted, "improved": tf.pairs_improved, "n_pairs": tf.n_pairs,
            "today": metrics.log_rmse(today.table, m.truth), "today_cv": today.cv_log_error,
            "tilt": metrics.log_rmse(tf.table, m.truth), "tilt_cv": tf.holdout_error,
            "plain_cv": tf.plain_holdout_error, "t": np.rad2deg(tf.tilt),
            "b": np.rad2deg(tf.azimuth) % 360.0, "cpu": cpu}


def adaptive_scan(plain: Basis, asym: Basis, m: bu.Material, cells: np.ndarray,
                  ph: np.ndarray, seed: int, refine_basis: bool, arc: str = "auto",
                  max_rotations: int | None = None) -> dict[str, Any]:
    """The product's default adaptive plan on one specimen, its rounds as the engine runs
    them (:class:`gonio.plans.rounds.ArcRounds`, :class:`gonio.plans.rounds.AdaptiveRounds`):
    ``arc`` ``"auto"`` (the first round with one opposite, the test, the fill round when
    asymmetric, the refinement in the arc chosen) or ``"half"`` (a fixed half turn). With
    ``refine_basis`` the refinement after an asymmetric verdict plans with the asymmetric
    basis (the product since issue 25's refinement basis), else with the default one (the
    product before). The readings, the verdict, the bases the rounds planned with and the
    log_rmse of the fit with the basis the verdict chooses. ``max_rotations``: the plan's cap
    on stage angles (default the plan's, 16)."""
    from gonio.plans.arc import arc_test

    plan = (AdaptivePlan() if max_rotations is None
            else AdaptivePlan(max_rotations=max_rotations))
    r0, limit = plan.initial_rotations, plan.max_rotations or 16
    refiner = PosteriorRefiner.for_cells(lambda: plain, cells, ph,
                                         (lambda: asym) if refine_basis else None)
    test: dict[str, Any] | None = None
    if arc == "auto":
        angles = first_round_angles(0.0, r0, 1)  # the design's pairs spread
        vals = bu.read(m, cells, ph, np.deg2rad(angles), seed)
        test = arc_test(angles, vals, 0.01)
    else:
        angles = [180.0 * k / r0 for k in range(r0)]
        vals = bu.read(m, cells, ph, np.deg2rad(angles), seed)
    last_round = 0
    if test is not None and not test["symmetric"]:
        fill = fill_after(0.0, r0, angles)
        vals = np.concatenate([vals, bu.read(m, cells, ph, np.deg2rad(fill), seed + 1)], axis=1)
        angles, last_round = angles + fill, 1
    span = 180.0 if test is None else float(test["arc_deg"])
    basis = refinement_basis(test)
    used: list[str] = []
    while True:
        budget = limit - len(angles)
        if last_round + 1 >= plan.max_rounds or budget <= 0:
            break
        new = refiner.next_angles(RoundRequest(angles, vals, budget, 0.01, plan.min_gain,
                                               (0.0, span), basis))
        used.append(str(refiner.basis_used))
        if not new:
            break
        extra = bu.read(m, cells, ph, np.deg2rad(new), seed + 1000 * (last_round + 1))
        vals = np.concatenate([vals, extra], axis=1)
        angles, last_round = angles + list(new), last_round + 1
    final = asym if basis == "asymmetric" else plain
    rec = reconstruct(final, cells, ph, np.deg2rad(angles), vals)
    return {"symmetric": test is None or bool(test["symmetric"]),
            "p": None if test is None else test["p_value"],
            "readings": len(cells) * len(angles), "angles": len(angles),
            "planned_with": sorted(set(used)),
            "log_rmse": metrics.log_rmse(rec.table, m.truth)}


ADAPTIVE_SETS = {"choice": "ASYM", "asym-fresh": "ASYM_FRESH", "fresh": "FRESH",
                 "fresh2": "FRESH2", "fresh3": "FRESH3", "fresh4": "FRESH4", "fresh5": "FRESH5"}
"""``--adaptive`` sets: the name of each module list of specimens."""


def adaptive_rows(plain: Basis, asym: Basis, d_half: tuple[np.ndarray, np.ndarray],
                  which: str, seeds: int, max_rotations: int | None = None,
                  symmetric: bool = True) -> None:
    """The adaptive auto-arc tables (``--adaptive``, module notes): the asymmetric specimens
    of ``which`` (``seeds`` noise seeds each), the refinement planned with the default basis
    (before) and with the basis finishing uses (after); then the symmetric ones.
    ``max_rotations``: the plan's cap on stage angles (default the plan's)."""
    specs = globals()[ADAPTIVE_SETS[which]]
    mats = asym_materials(specs=specs)
    print(f"\n{which} set ({ADAPTIVE_SETS[which]}), the default adaptive plan with arc auto, the "
          f"default design's 10 pairs, max_rotations {max_rotations or 'default'}, "
          f"{seeds} noise seed(s) each (means over seeds); the "
          "refinement planned with the default basis (before) or the asymmetric one (after)")
    print("\n| specimen | verdict | readings before | log_rmse before | readings after | "
          "**log_rmse after** | planned with (after) |")
    print("|---|---|---|---|---|---|---|")
    rows = []
    for i, m in enumerate(mats):
        got: dict[bool, list[dict[str, Any]]] = {False: [], True: []}
        for k in range(seeds):
            for refine in (False, True):
                got[refine].append(adaptive_scan(plain, asym, m, *d_half, 500 + i + 100 * k,
                                                 refine, max_rotations=max_rotations))
        b, a = got[False], got[True]
        found = sum(not r["symmetric"] for r in a)
        row = [np.mean([r["readings"] for r in b]), np.mean([r["log_rmse"] for r in b]),
               np.mean([r["readings"] for r in a]), np.mean([r["log_rmse"] for r in a])]
        rows.append(row)
        used = sorted({u for r in a for u in r["planned_with"]})
        print(f"| {m.name} | {found} of {seeds} NOT symmetric | {row[0]:.0f} | {row[1]:.4f} | "
              f"{row[2]:.0f} | {row[3]:.4f} | {', '.join(used) or 'none'} |", flush=True)
    x = np.array(rows)
    print(f"| **mean** | | {x[:, 0].mean():.1f} | {x[:, 1].mean():.4f} | {x[:, 2].mean():.1f} | "
          f"**{x[:, 3].mean():.4f}** | |")
    worse = x[:, 3] - x[:, 1]
    print(f"\nafter against before: worst {worse.max():+.4f}, best {worse.min():+.4f}, "
          f"{int((worse > 0.01).sum())} of {len(x)} worse by more than 0.01")
    if not symmetric:
        return
    sym = asym_materials(tilted=False, specs=specs)
    if which == "choice":
        sym = bu.aniso_materials() + sym
    print(f"\nsymmetric specimens ({len(sym)}), {seeds} noise seeds each (means over seeds): "
          "the default adaptive plan over a fixed half turn, and with arc auto (before / after: "
          "the same scan unless the test calls it asymmetric; both are run then)")
    print("\n| specimen | half turn: readings | half turn | auto: readings | auto before | "
          "auto after | called asymmetric |")
    print("|---|---|---|---|---|---|---|")
    srows, alarms, total = [], 0, 0
    for j, m in enumerate(sym):
        half, before, after, flagged = [], [], [], 0
        for k in range(seeds):
            seed = 9000 + 37 * j + k
            half.append(adaptive_scan(plain, asym, m, *d_half, seed, True, "half",
                                      max_rotations))
            r = adaptive_scan(plain, asym, m, *d_half, seed, True, "auto", max_rotations)
            after.append(r)
            before.append(r if r["symmetric"] else
                          adaptive_scan(plain, asym, m, *d_half, seed, False, "auto",
                                        max_rotations))
            flagged += not r["symmetric"]
        alarms, total = alarms + flagged, total + seeds
        srows.append([np.mean([r["readings"] for r in half]),
                      np.mean([r["log_rmse"] for r in half]),
                      np.mean([r["readings"] for r in after]),
                      np.mean([r["log_rmse"] for r in before]),
                      np.mean([r["log_rmse"] for r in after])])
        sr = srows[-1]
        print(f"| {m.name} | {sr[0]:.0f} | {sr[1]:.4f} | {sr[2]:.0f} | {sr[3]:.4f} | "
              f"{sr[4]:.4f} | {flagged} of {seeds} |", flush=True)
    y = np.array(srows)
    print(f"| **mean** | {y[:, 0].mean():.1f} | {y[:, 1].mean():.4f} | {y[:, 2].mean():.1f} | "
          f"{y[:, 3].mean():.4f} | {y[:, 4].mean():.4f} | {alarms} of {total} |")


def log_average(a: BRDFTable, b: BRDFTable, eps: float = 1e-4) -> BRDFTable:
    """The two fits averaged in log: ``sqrt((a + eps) (b + eps)) - eps`` cell by cell (1/sr;
    ``eps`` keeps a zero of one fit from zeroing the average). Its log error is at most the
    mean of the two fits' (the log table's distance is a norm), less when they err apart."""
    va = np.asarray(a.values, dtype=float)
    vb = np.asarray(b.values, dtype=float)
    avg = np.sqrt((np.maximum(va, 0) + eps) * (np.maximum(vb, 0) + eps)) - eps
    return BRDFTable.trusted(avg, a.channels, f"mean of {a.name} and {b.name}")


def full_turn_tilt(plain: Basis, m: bu.Material, cells: np.ndarray, ph: np.ndarray, r: int,
                   seed: int) -> dict[str, Any]:
    """A symmetric specimen read over a full turn: the plain joint fit against the tilt fit on
    the same readings (the tilt fit must find no lean and cost nothing)."""
    alpha = uniform_stage_angles(r)
    vals = bu.read(m, cells, ph, alpha, seed)
    plain_fit = reconstruct(plain, cells, ph, alpha, vals)
    t0 = time.process_time()
    tf = fit_tilt(plain, cells, ph, alpha, vals, reference=plain)
    cpu = time.process_time() - t0
    return {"plain": metrics.log_rmse(plain_fit.table, m.truth), "cpu": cpu,
            "accepted": tf.accepted, "improved": tf.pairs_improved, "n_pairs": tf.n_pairs,
            "tilt": metrics.log_rmse(tf.table, m.truth), "t": np.rad2deg(tf.tilt),
            "b": np.rad2deg(tf.azimuth) % 360.0, "tilt_cv": tf.holdout_error,
            "plain_cv": plain_fit.cv_log_error}


def tilt_rows(plain: Basis, asym: Basis, d_half: tuple[np.ndarray, np.ndarray],
              which: str, rotations: int) -> None:
    """The tilt fit's study (``--tilt``): ``which`` is ``choice`` (the 8 specimens above, where
    any setting was chosen), ``fresh`` (:data:`FRESH`, tested once) or ``symmetric``
    (bench_unseen's six anisotropic specimens, untilted, read over a full turn)."""
    if which == "symmetric":
        print(f"\nsymmetric specimens, the default design's 10 pairs, {2 * rotations} angles over "
              "a full turn: plain joint fit against the tilt fit on the same readings")
        print("\n| specimen | plain | tilt fit | rule | pairs improved | fitted tilt (deg) / "
              "azimuth | held-out: plain / tilt | tilt CPU s |")
        print("|---|---|---|---|---|---|---|---|")
        rows = []
        for j, m in enumerate(bu.aniso_materials()):
            r = full_turn_tilt(plain, m, *d_half, 2 * rotations, 9000 + 37 * j)
            rule = r["tilt"] if r["accepted"] else r["plain"]
            rows.append((r["plain"], r["tilt"], r["t"], rule, r["cpu"]))
            print(f"| {m.name} | {r['plain']:.4f} | {r['tilt']:.4f} | {rule:.4f} | "
                  f"{r['improved']} of {r['n_pairs']} | {r['t']:.1f} / {r['b']:.0f} | "
                  f"{r['plain_cv']:.4f} / {r['tilt_cv']:.4f} | {r['cpu']:.1f} |", flush=True)
        a = np.array(rows)
        print(f"| **mean** | {a[:, 0].mean():.4f} | {a[:, 1].mean():.4f} | "
              f"**{a[:, 3].mean():.4f}** | | {int((a[:, 2] == 0).sum())} of {len(a)} at 0 | | "
              f"{a[:, 4].mean():.1f} |")
        return
    specs = {"choice": ASYM, "fresh": FRESH, "fresh2": FRESH2, "fresh3": FRESH3,
             "fresh4": FRESH4}[which]
    mats = asym_materials(specs=specs)
    print(f"\n{which} set, auto arc R = {rotations}, the default design's 10 pairs: today's "
          "path (the basis the verdict chooses) against the tilt fit on the same readings, "
          "and the two averaged in log")
    print("\n| specimen | readings | today | tilt fit | rule | average | pairs improved | "
          "fitted t / b (deg) | truth t / b | held-out: today / tilt | tilt CPU s |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    rows = []
    for i, (m, spec) in enumerate(zip(mats, specs, strict=True)):
        r = tilt_scan(plain, asym, m, *d_half, rotations, 500 + i)
        # The rule (tilt.tilt_decision, chosen on the choice set): the tilt fit when it lowers
        # the held-out error of at least 70 % of the pairs against today's basis.
        rule = r["tilt"] if r["accepted"] else r["today"]
        truth_b = (spec[2] + spec[4]) % 360.0  # the lean's azimuth in the specimen frame
        rows.append((r["today"], r["tilt"], rule, r["readings"], r["cpu"], r["average"]))
        print(f"| {m.name} | {r['readings']} | {r['today']:.4f} | {r['tilt']:.4f} | {rule:.4f} | "
              f"{r['average']:.4f} | {r['improved']} of {r['n_pairs']} | "
              f"{r['t']:.1f} / {r['b']:.0f} | "
              f"{spec[1]:.0f} / {truth_b:.0f} | "
              f"{r['today_cv']:.4f} / {r['tilt_cv']:.4f} | {r['cpu']:.1f} |", flush=True)
    a = np.array(rows)
    print(f"| **mean** | {a[:, 3].mean():.0f} | {a[:, 0].mean():.4f} | {a[:, 1].mean():.4f} "
          f"| **{a[:, 2].mean():.4f}** | **{a[:, 5].mean():.4f}** | | | | | "
          f"{a[:, 4].mean():.1f} |")
    for label, col in (("rule", 2), ("average", 5)):
        print(f"\n{label} against today: worst {np.max(a[:, col] - a[:, 0]):+.4f}, "
              f"{int(np.sum(a[:, col] - a[:, 0] > 0.01))} specimens worse by more than 0.01")


def disagree_round(plain: Basis, ref: Basis, m: bu.Material, cells: np.ndarray, ph: np.ndarray,
                   angles: list[float], vals: np.ndarray, count: int, refits: list[str],
                   scores: list[str], seed: int) -> dict[tuple[str, str], dict[str, Any]]:
    """The disagreement round after a first pass (``angles`` deg, ``vals``; docs/science.md
    7.4): today's fit (``ref``) and the tilt fit (``plain``) predict every pair at the
    candidate angles, ``count`` angles are read where they disagree most, the fit that
    predicted them better is kept and refitted on every reading. Per score in ``scores``
    (``noise``: noise-scaled chi-square; ``metric``: the cosine-weighted log of log_rmse), for
    the placement and the choice alike, and per refit in ``refits`` (``search``: the tilt
    searched again; ``lean``: refitted at the first pass's lean)."""
    from gonio.brdf.reconstruction import disagree as dg
    from gonio.brdf.reconstruction.tilt import reconstruct_through

    alpha = np.deg2rad(angles)
    t0 = time.process_time()
    today1 = reconstruct(ref, cells, ph, alpha, vals)
    tf1 = fit_tilt(plain, cells, ph, alpha, vals)
    cand = dg.candidate_angles()
    peak = dg.pair_peaks(vals)
    cos_i = dg.pair_cosines(cells, ph)
    pa = dg.predict_readings(today1.table, cells, ph, np.deg2rad(cand))
    pb = dg.predict_readings(tf1.table, cells, ph, np.deg2rad(cand))
    base_cpu = time.process_time() - t0
    out: dict[tuple[str, str], dict[str, Any]] = {}
    for score in scores:
        t1 = time.process_time()
        spread = (dg.metric_disagreement(pa, pb, cos_i) if score == "metric"
                  else dg.disagreement(pa, pb, peak))
        new = dg.choose_angles(spread, cand, angles, count)
        new_alpha = np.deg2rad(new)
        nv = bu.read(m, cells, ph, new_alpha, seed)
        qa = dg.predict_readings(today1.table, cells, ph, new_alpha)
        qb = dg.predict_readings(tf1.table, cells, ph, new_alpha)
        if score == "noise":
            e_today, e_tilt = dg.chi_square(qa, nv, peak), dg.chi_square(qb, nv, peak)
        elif score == "noise-median":
            e_today = float(np.median(dg.chi_terms(qa, nv, peak)))
            e_tilt = float(np.median(dg.chi_terms(qb, nv, peak)))
        else:
            e_today, e_tilt = dg.metric_error(qa, nv, cos_i), dg.metric_error(qb, nv, cos_i)
        all_alpha = np.concatenate([alpha, new_alpha])
        all_vals = np.concatenate([vals, nv], axis=1)
        common = {"first_today": metrics.log_rmse(today1.table, m.truth),
                  "first_tilt": metrics.log_rmse(tf1.table, m.truth),
                  "readings": all_vals.shape[0] * all_vals.shape[1], "e_today": e_today,
                  "e_tilt": e_tilt, "n_new": nv.size, "angles": new}
        round_cpu = time.process_time() - t1
        today_table = None
        for refit in refits:
            t2 = time.process_time()
            t, b = tf1.tilt, tf1.azimuth
            if tf1.tilt > 0 and e_tilt < e_today:
                kept = "tilt"
                if refit in ("search", "near"):
                    near = {} if refit == "search" else {
                        "tilts_deg": [x for x in np.rad2deg(t) + np.array([-5.0, 0.0, 5.0])
                                      if x > 0],
                        "azimuths_deg": list(np.rad2deg(b) + np.arange(-30.0, 31.0, 15.0))}
                    tf2 = fit_tilt(plain, cells, ph, all_alpha, all_vals, **near)
                    table, t, b = tf2.table, tf2.tilt, tf2.azimuth
                else:
                    table = reconstruct_through(plain, cells, ph, all_alpha, all_vals, t, b)[1]
            else:
                kept = "today" if tf1.tilt > 0 else "same (no lean)"
                if today_table is None:
                    today_table = reconstruct(ref, cells, ph, all_alpha, all_vals).table
                table = today_table
            out[(refit, score)] = {
                **common, "round": metrics.log_rmse(table, m.truth), "kept": kept,
                "t": np.rad2deg(t), "b": np.rad2deg(b) % 360.0,
                "cpu": base_cpu + round_cpu + time.process_time() - t2}
    return out


def disagree_rows(plain: Basis, asym: Basis, d_half: tuple[np.ndarray, np.ndarray],
                  which: str, firsts: list[int], refits: list[str], scores: list[str]
                  ) -> None:
    """The disagreement round's study (``--disagree SET``, docs/science.md 7.4): per specimen,
    today's path and the tilt fit at 120 readings (:func:`tilt_scan`, R = 6) against the round
    after a first pass of ``R`` in ``firsts`` (the auto-arc path: ``20 R`` readings when
    asymmetric) filled up to 120 readings, for each refit in ``refits``. ``symmetric``:
    bench_unseen's six anisotropic specimens, the first pass ``2R`` uniform angles over a full
    turn, against their plain fit of 12 uniform angles (:func:`full_turn_tilt`)."""
    from gonio.plans.arc import arc_test

    cells, ph = d_half
    n = len(cells)
    if which == "symmetric":
        mats, specs = bu.aniso_materials(), None
    else:
        specs = {"choice": ASYM, "fresh": FRESH, "fresh2": FRESH2, "fresh3": FRESH3}[which]
        mats = asym_materials(specs=specs)
    variants = [(r, f, s) for r in firsts for f in refits for s in scores]
    rows: dict[tuple[int, str, str], list[tuple[float, float, float, int]]] = {
        v: [] for v in variants}
    lines: dict[tuple[int, str, str], list[str]] = {v: [] for v in variants}
    for i, m in enumerate(mats):
        if which == "symmetric":
            seed = 9000 + 37 * i
            ref = full_turn_tilt(plain, m, cells, ph, 12, seed)
            today, tilt = ref["plain"], ref["tilt"]
        else:
            seed = 500 + i
            ref = tilt_scan(plain, asym, m, cells, ph, 6, seed)
            today, tilt = ref["today"], ref["tilt"]
        for r_first in firsts:
            if which == "symmetric":
                angles = [float(a) for a in np.rad2deg(uniform_stage_angles(2 * r_first))]
                vals = bu.read(m, cells, ph, np.deg2rad(angles), seed + 1)
                basis = plain
            else:
                angles = first_round_angles(0.0, r_first, 1)
                vals = bu.read(m, cells, ph, np.deg2rad(angles), seed + 1)
                test = arc_test(angles, vals, 0.01)
                basis = plain if test["symmetric"] else asym
                if not test["symmetric"]:
                    fill = fill_angles(0.0, r_first, 1)
                    vals = np.concatenate(
                        [vals, bu.read(m, cells, ph, np.deg2rad(fill), seed + 2)], axis=1)
                    angles += fill
            count = max(0, (120 - n * len(angles)) // n)
            res = disagree_round(plain, basis, m, cells, ph, angles, vals, count, refits,
                                 scores, seed + 3)
            for (refit, score), d in res.items():
                key = (r_first, refit, score)
                rows[key].append((today, tilt, d["round"], d["readings"]))
                lines[key].append(
                    f"| {m.name} | {today:.4f} | {tilt:.4f} | **{d['round']:.4f}** | "
                    f"{d['readings']} | {d['kept']} | {d['first_today']:.4f} / "
                    f"{d['first_tilt']:.4f} | {d['e_today']:.4g} / {d['e_tilt']:.4g} "
                    f"({d['n_new']}) | {d['t']:.1f} / {d['b']:.0f} | "
                    f"{', '.join(f'{a:g}' for a in d['angles'])} | {d['cpu']:.1f} |")
                print(f"  {which} {m.name} R={r_first} {refit} {score}: today {today:.4f} tilt "
                      f"{tilt:.4f} round {d['round']:.4f} kept {d['kept']}", flush=True)
    for key in variants:
        r_first, refit, score = key
        print(f"\n{which} set, first pass R = {r_first} ({n * 2 * r_first} readings when "
              f"asymmetric) + the disagreement round to 120, refit {refit!r}, score {score!r}; "
              "today and tilt fit at 120 readings (R = 6)")
        print("\n| specimen | today | tilt fit | round | readings | kept | first pass: today "
              "/ tilt | round's error: today / tilt (readings) | final t / b (deg) | round "
              "angles (deg) | round CPU s |")
        print("|---|---|---|---|---|---|---|---|---|---|---|")
        for line in lines[key]:
            print(line)
        a = np.array(rows[key], dtype=float)
        print(f"| **mean** | {a[:, 0].mean():.4f} | {a[:, 1].mean():.4f} | "
              f"**{a[:, 2].mean():.4f}** | {a[:, 3].mean():.0f} | | | | | | |")
        worse = a[:, 2] - a[:, 0]
        print(f"\nround against today: mean {a[:, 2].mean() - a[:, 0].mean():+.4f} "
              f"({100 * (a[:, 2].mean() / a[:, 0].mean() - 1):+.1f} %), worst "
              f"{worse.max():+.4f}, {int(np.sum(worse > 0.01))} specimens worse by more than "
              "0.01", flush=True)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=5,
                    help="noise seeds per symmetric specimen for the false-alarm count")
    ap.add_argument("--false-alarm", type=float, default=0.01,
                    help="the symmetry test's false-alarm rate")
    ap.add_argument("--tilted-facets", type=int, default=None, metavar="N",
                    help="train the asymmetric basis with N tilted-facet materials instead of "
                         "the library's count (a study of how many the prior needs)")
    ap.add_argument("--pairs", type=int, default=10,
                    help="pairs of the asymmetric-basis rows (the goal is stated for 10)")
    ap.add_argument("--auto", action="store_true",
                    help="only the auto-arc path's tables (module notes)")
    ap.add_argument("--layout", choices=sorted(LAYOUTS), default="one",
                    help="the auto arc's first-round layout (with --auto; module LAYOUTS)")
    ap.add_argument("--set", choices=("choice", "fresh"), default="choice",
                    help="with --auto: the specimens (fresh: ASYM_FRESH, run once)")
    ap.add_argument("--tilt", choices=("choice", "fresh", "fresh2", "fresh3", "fresh4",
                                       "symmetric"),
                    default=None,
                    help="only the tilt fit's study on that set (module notes)")
    ap.add_argument("--disagree", choices=("choice", "fresh", "fresh2", "fresh3", "symmetric"),
                    default=None, help="only the disagreement round's study on that set "
                                       "(docs/science.md 7.4)")
    ap.add_argument("--first-rotations", type=int, nargs="+", default=[4],
                    help="with --disagree: R of the first pass (20 R readings when "
                         "asymmetric; the round fills up to 120)")
    ap.add_argument("--refit", nargs="+", choices=("search", "near", "lean"),
                    default=["near"],
                    help="with --disagree: the tilt fit kept is searched again on every "
                         "reading (search), searched within 5 deg of tilt and 30 of azimuth "
                         "of the first pass's lean (near) or refitted at that lean (lean)")
    ap.add_argument("--score", nargs="+", choices=("noise", "noise-median", "metric"),
                    default=["noise"],
                    help="with --disagree: the units the round is placed and judged in: "
                         "noise-scaled chi-square (noise; noise-median: judged by the median "
                         "reading's term) or the cosine-weighted log of log_rmse (metric)")
    ap.add_argument("--adaptive", choices=sorted(ADAPTIVE_SETS), default=None,
                    help="only the adaptive auto-arc tables on that set (module notes)")
    ap.add_argument("--max-rotations", type=int, default=None,
                    help="with --adaptive: the plan's cap on stage angles (default the plan's)")
    ap.add_argument("--no-symmetric", action="store_true",
                    help="with --adaptive: the asymmetric specimens only")
    ap.add_argument("--rotations", type=int, default=6,
                    help="R of the auto arc for --tilt (6: 120 readings when asymmetric)")
    args = ap.parse_args(argv)
    if args.tilted_facets is not None:
        from gonio.brdf.materials import library

        library.ASYMMETRIC_FAMILY_COUNTS["tilted-facet"] = args.tilted_facets
        library._specs.cache_clear()
    print(f"$ {' '.join(['python', *sys.argv])}")
    t0 = time.perf_counter()
    mats = asym_materials()
    plain = default_basis()
    asym = default_basis(asymmetric=True)
    d_half, d_full = design(plain, 180.0), design(plain, 360.0)
    if args.adaptive is not None:
        adaptive_rows(plain, asym, d_half, args.adaptive, args.seeds, args.max_rotations,
                      not args.no_symmetric)
        print(f"total {time.perf_counter() - t0:.0f} s")
        return 0
    if args.disagree is not None:
        disagree_rows(plain, asym, d_half, args.disagree, args.first_rotations, args.refit,
                      args.score)
        print(f"total {time.perf_counter() - t0:.0f} s")
        return 0
    if args.tilt is not None:
        tilt_rows(plain, asym, d_half, args.tilt, args.rotations)
        print(f"total {time.perf_counter() - t0:.0f} s")
        return 0
    if args.auto:
        auto_rows(plain, asym, d_half, args.seeds, args.layout, args.set == "fresh")
        print(f"total {time.perf_counter() - t0:.0f} s")
        return 0
    d_asym = design(asym, 360.0, args.pairs)
    noise = NoiseModel(0.01)
    print(f"ready in {time.perf_counter() - t0:.0f} s")
    cols = ["half r=8 (80)", "full r=8 (80)", f"asym full r=8 ({8 * args.pairs})",
            f"asym full r=12 ({12 * args.pairs})", "asym full r=12, default pairs (120)",
            "ceiling default", "ceiling asym"]
    print("\n| specimen | " + " | ".join(cols) + " | twofold p (verdict, pairs flagged) |")
    print("|---" * (len(cols) + 2) + "|")
    rows = []
    for i, m in enumerate(mats):
        seed = 500 + i
        half = scan(plain, m, *d_half, 8, 180.0, seed)[0]
        full, alpha, vals = scan(plain, m, *d_full, 8, 360.0, seed)
        a8 = scan(asym, m, *d_asym, 8, 360.0, seed)[0]
        a12 = scan(asym, m, *d_asym, 12, 360.0, seed)[0]
        a12d = scan(asym, m, *d_half, 12, 360.0, seed)[0]
        c0 = metrics.log_rmse(bu.ceiling(plain, m.truth), m.truth)
        c1 = metrics.log_rmse(bu.ceiling(asym, m.truth), m.truth)
        t = twofold_test(alpha, vals, noise, false_alarm=args.false_alarm)
        verdict = "symmetric" if t.overall_symmetric else "NOT symmetric"
        rows.append([half, full, a8, a12, a12d, c0, c1])
        print(f"| {m.name} | " + " | ".join(f"{v:.4f}" for v in rows[-1])
              + f" | {t.total_p_value:.2g} ({verdict}, {int((~t.symmetric).sum())} of "
              f"{t.symmetric.size}) |", flush=True)
    mean = np.mean(rows, axis=0)
    print("| **mean** | " + " | ".join(f"{v:.4f}" for v in mean) + " | |")
    goal = mean[3] <= 0.06 and args.pairs == 10
    print(f"\n(asymmetric rows with {args.pairs} pairs) goal asymmetric mean log_rmse <= 0.06 "
          "within 120 readings at 10 pairs: "
          f"{'met' if goal else 'NOT met'} ({mean[3]:.4f}; with the default design's pairs, "
          f"as a scan reads them: {'met' if mean[4] <= 0.06 else 'NOT met'}, {mean[4]:.4f})")

    # False alarms: symmetric specimens read over a full turn, several noise seeds each.
    sym = bu.aniso_materials() + asym_materials(tilted=False)
    flagged = total = 0
    alarms: list[str] = []
    for j, m in enumerate(sym):
        for s in range(args.seeds):
            _, alpha, vals = scan(plain, m, *d_full, 8, 360.0, 9000 + 37 * j + s)
            t = twofold_test(alpha, vals, noise, false_alarm=args.false_alarm)
            total += 1
            if not t.overall_symmetric:
                flagged += 1
                alarms.append(f"{m.name} (seed {s}, p {t.total_p_value:.2g})")
    print(f"\nsymmetric scans called asymmetric: {flagged} of {total} "
          f"({len(sym)} specimens x {args.seeds} seeds; false-alarm rate {args.false_alarm}); "
          f"goal at most 1 in 20: {'met' if flagged * 20 <= total else 'NOT met'}")
    for a in alarms:
        print(f"  {a}")
    print(f"total {time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
