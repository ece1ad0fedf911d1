"""Benchmark: is ``predicted_log_rmse`` an estimate a lab can trust? (issue 23 item 4)

Run from the project root (needs mitsuba: ``pip install 'gonio[rgl]'``)::

    nice -n 10 .venv/bin/python bench/bench_selfestimate.py [--rows FILE]

Materials, all held out of the basis they are reconstructed with (the helpers of
``bench_unseen.py`` and ``bench_asymmetric.py``, whose caches this shares):

* the eleven measured RGL materials, each with ``default_basis(exclude=[it])``;
* ``bench_unseen.py``'s six anisotropic mitsuba specimens (default basis);
* ``bench_asymmetric.py``'s eight specimens without twofold symmetry (tilted facets: structure
  the default basis cannot hold) and their eight untilted versions (default basis);
* every fourth material of the library's families without twofold symmetry (tilted facets,
  pile, sawtooth; :func:`library_asymmetric`), none of them in the default basis;
* sixteen fresh mitsuba specimens (:data:`FRESH`, default basis).

Plans (1 % noise, readings at the exact pair directions): the default scan (10 pairs designed
by the joint fit's expected error on the material's basis, 8 stage angles over half a turn),
the same pairs at 4 and at 16 angles, and the MA68 and MA98 presets at 8 angles.

Split (:func:`which_set`), three sets:

* **calibration** ("cal"): the six anisotropic mitsuba specimens, the measured materials at
  even positions (alphabetical, 0-based) and the library's asymmetric materials. The constants
  of the final mapping (:func:`gonio.brdf.reconstruction.selfcheck.final_log_rmse`:
  ``FINAL_PREDICTED_FACTOR``, ``FINAL_COVERAGE_SCALE``, ``FINAL_FLAGGED_FACTOR``) and of its
  interval (``UPPER_FACTOR``) are fitted on it alone;
* **choice**: the measured materials at positions 1, 5, 9 and the tilted / untilted
  normal-mapped mitsuba specimens of ``bench_asymmetric.ASYM`` at even positions: the
  candidate forms of the mapping were compared on it, and one was chosen;
* **test**: the measured materials at positions 3, 7 and the specimens at odd positions,
  reported once, after the choice (a specimen and its untilted version are in the same set);
* **fresh**: sixteen mitsuba specimens (:data:`FRESH`) added after that report, scanned once;
* **fresh-inplane**: sixteen more (:data:`FRESH_INPLANE`), written down with the in-plane candidate
  (:func:`in_plane_study`) before any scan of them: that candidate's blind set;
* **fresh-confirm**: sixteen more (:data:`FRESH_CONFIRM`), written down with the rule of the
  candidate's confirmation (:func:`confirm_in_plane`) before any scan of them;
* **fresh-wide**: twelve more (:data:`FRESH_WIDE`), written down with the rule of the highlight
  widening (below, :func:`highlight_study`) and committed before any scan of them;
* **fresh-coat**: twelve more (:data:`FRESH_COAT`), written down with the rule of the
  leave-one-pair-out under-prediction term (below, :func:`under_study`) and committed before
  any scan of them;
* **fresh-high**: twelve more (:data:`FRESH_HIGH`), written down with the rule of the
  over-prediction study (below, :func:`high_study`) and committed before any scan of them;
* **fresh-cov**: twelve more (:data:`FRESH_COV`), written down with the rule of the coverage
  shrink (below, :func:`cov_study`) and committed before any scan of them; they are scanned
  only after that study's choice is printed (:func:`main`).

**The highlight widening (2026-11-28; rule written down and committed before any row of the
statistic was computed, so before any set, the calibration set included, was looked at).**
Question: are the scans whose estimate is more than 2x too low the scans whose highlight is not
read (``highlight_excess`` above ``gonio.brdf.highlightread.EXCESS_LIMIT`` = 3.4), and does
widening the estimate by that witness fix them without costing the scans within x2? Every row
stores ``highlight_excess`` (:func:`gonio.brdf.highlightread.highlight_read` on the
reconstruction and its readings, clipped at 0, as ``gonio/finishing.py`` calls it; NaN, no
positive reading, is taken as 1). :func:`highlight_cross_table` prints per set the scans more
than 2x low with their excess and flagged / not flagged x low / within x2 / high. The rule:

* **Two forms, one parameter each** (``est`` the shipped final mapping before the peak floor,
  ``e`` the excess; both under the shipped floor, ``max(., peak_excess_log_rmse)``):
  ``"widen"``: ``est max(1, e / 3.4)^g``, ``g`` over 0-2 in steps of 0.05 (only flagged scans
  move); ``"variance"``: ``s ln(max(e, 1))`` added as a variance beside the coverage term
  (``final_log_rmse(..., in_plane=s ln(max(e, 1)))``, i.e. ``k ln(e)^2`` with ``k = s^2``),
  ``s`` over 0-0.15 in steps of 0.0025 (every scan with ``e`` > 1 moves, more the larger).
* **Fit (calibration set only, 145 scans).** Over both grids: the fewest scans more than 2x
  low, then the most within x2, then the form ``"widen"`` before ``"variance"``, then the
  smaller parameter. A parameter of 0 (the shipped estimate) ends the study: not adopted.
* **Choice set (55 scans).** Adopted only if the candidate leaves no more choice scans more
  than 2x low than the shipped estimate and at most one fewer within x2.
* **Test and fresh sets** (test, fresh, fresh-inplane, fresh-confirm: 290 scans), printed once
  after the choice: adopted only if the candidate leaves no more of them more than 2x low.
* **fresh-wide** (60 scans), printed last: adopted only if the candidate leaves no more of them
  more than 2x low (within x2 reported, not a condition).

Result (one run): ``"variance"``, ``s`` = 0.025, passed every step and is shipped as
``selfcheck.FINAL_HIGHLIGHT_SCALE`` (docs/science.md 7.1.1). Since then the rows' shipped
estimate (``widened``) carries the term; the study compares against the mapping without it
(:func:`before_highlight`), and the older candidates (the rejected refit, the in-plane term)
are still built on the mapping without it.

**The leave-one-pair-out under-prediction term (2026-11-28; rule written down and committed
before any row of its witness was computed).** The clear-coated ``f6-clearcoat-white`` of
fresh-wide is more than 2x low at every plan. Looked at on that specimen alone (so fresh-wide is
not blind for this term; docs/notes/2026-11-28-clearcoat-blind-spot.md): its truth carries a
mirror spike at ``th_h`` = 0 (about 200-700 1/sr over a 0.26 body) that holds 0.19 % of the
metric's weight and 75-99 % of its squared error. The designed pairs put one pair on it, which
the fit holds (chi2 below 1) but which the other nine pairs predict ``e^4.9`` times too low;
the model's leave-one-pair-out witness ``cv_sample_error`` is a relative error and cannot
exceed 1 for a pair predicted too low, so it reads 0.42. The witness studied: ``u`` =
``Reconstruction.cv_log_under``, the root mean square over the readings of how far each
reading lies above the fit to the other pairs, ``max(0, ln(1 + f cos ti) - ln(1 + f_loo cos
ti))`` (readings alone). The presets read no pair within 2.5 degrees of ``th_h`` = 0 there, and
no witness of the readings is expected to see the spike: this term cannot mend those scans.

* **Form, one parameter** (``est`` the shipped final mapping, highlight term included):
  ``v u`` added as a variance beside the coverage and highlight terms
  (``final_log_rmse(..., in_plane=v u, highlight_excess=e)``), under the peak floor; ``v``
  over 0-0.10 in steps of 0.0025 (:data:`UNDER_GRID`). The unsigned ``cv_log_error`` at the
  chosen ``v`` is printed beside it for information, not chosen from.
* **Fit (calibration set only).** The calibration set has no scan more than 2x low under the
  shipped estimate, so there is nothing to minimise there: the admissible values are those
  leaving the calibration set no more scans more than 2x low and no fewer within x2 than the
  shipped estimate (the widening the calibration set allows at no cost).
* **Choice.** Of the admissible values, the largest that leaves the choice set no more scans
  more than 2x low and no fewer within x2 than the shipped estimate. None above 0: not adopted.
* **Test and fresh sets** (test, fresh, fresh-inplane, fresh-confirm: 290 scans), printed once
  after the choice: adopted only if no more of them more than 2x low (within x2 reported).
* **fresh-wide** (60 scans; not blind, the blind spot was found there): adopted only if fewer
  of them more than 2x low.
* **fresh-coat** (60 scans, :data:`FRESH_COAT`, blind), printed last: adopted only if no more
  of them more than 2x low (within x2 reported, not a condition).

Result (one run): ``v`` = 0.0425 (the calibration set keeps 86 of 145 within x2 up to there, 85
from 0.045); it passed every step (test and fresh 187 / 3 -> 187 / 3, fresh-wide 35 / 6 ->
38 / 3, fresh-coat 22 / 25 -> 31 / 16, within x2 / more than 2x low) and is shipped as
``selfcheck.FINAL_UNDER_SCALE`` (docs/science.md 7.1.1). Since then the rows' shipped estimate
(``widened``) carries the term; :func:`under_candidate` at ``v`` = 0 is the mapping without it.

**The over-predictions (2026-11-28; rule written down and committed before any candidate was
computed on the choice, test, fresh or blind sets).** Most misses are over-predictions: the
shipped estimate is more than 2x the truth on 59 of the 145 calibration scans and none is more
than 2x low. :func:`overprediction_cross_table` prints, on the calibration set only, plan x
kind of material (within x2 / low / high) and, for the scans more than 2x high, which part of
the mapping is the largest (the model's part ``k predicted``, the coverage term, the highlight
term, the under term, the peak floor or the misfit floor). Looked at on the calibration set
alone: 51 of the 59 are the library's materials without twofold symmetry (pile, sawtooth,
tilted facets), the measured materials 1 of 30; the model's part is the largest in 40, the
coverage term in 18 (MA68 9 of them). Over the 37 such library scans not flagged the median
``cv_sample_error`` is 1.0 and the median ``cv_log_error`` 0.021. The model's witness of what the
basis cannot represent is
a relative error, dominated by dim readings that ``ln(1 + f cos ti)`` hardly weighs; the
readings' own leave-one-pair-out error in the metric's units says how much of it the metric
sees. Both forms below were explored on the calibration set (and only there) before this
was written: the cap at ``p`` = 0.5 gave 93 of 145 within x2 with none low, the in-plane shrink
at 0.4 gave 92; nothing of either has been computed on any other set.

* **Two forms, one parameter each** (the shipped mapping otherwise, highlight and under terms
  and both floors included; :func:`high_candidate`):
  ``"outside-cap"``: for a scan whose misfit is not flagged, the model's outside part
  (:func:`~gonio.brdf.reconstruction.selfcheck.estimate_parts`) is capped at
  ``p cv_log_error`` before the factor, ``p`` over 0.25-5 in steps of 0.25 (flagged scans
  unchanged: there the basis cannot hold the readings and their own floor stands);
  ``"inplane-coverage"``: the coverage term times ``1 - p`` for a layout with every pair in
  the plane of incidence (``out_of_plane`` share 0: MA68), ``p`` over 0-0.70 in steps of 0.05.
* **Fit (calibration set only, 145 scans).** Over both grids: the fewest scans more than 2x
  low (the shipped estimate has none), then the most within x2, then ``"outside-cap"`` before
  ``"inplane-coverage"``, then the value nearer the shipped mapping (the larger cap, the
  smaller shrink). No gain within x2 at no more low ends the study: not adopted.
* **Choice set (55 scans).** Adopted only if the candidate leaves no more choice scans more
  than 2x low than the shipped estimate and strictly more within x2.
* **Test and fresh sets** (test, fresh, fresh-inplane, fresh-confirm: 290 scans), printed once
  after the choice: adopted only if no more of them more than 2x low (within x2 reported).
* **fresh-wide and fresh-coat** (120 scans; blind to this candidate, looked at for earlier
  terms): adopted only if no more of them more than 2x low.
* **fresh-high** (60 scans, :data:`FRESH_HIGH`, written down with this rule and committed
  before any scan of them), printed last: adopted only if no more of them more than 2x low
  (within x2 reported, not a condition).
* **The interval.** The upper end stays ``UPPER_FACTOR`` times the estimate; the truth above
  it is printed per set for the shipped estimate and the candidate. If the candidate's
  calibration p98 of ``true / estimate`` over the scans not flagged
  (:func:`~gonio.brdf.reconstruction.selfcheck.upper_factor_from`) exceeds ``UPPER_FACTOR``,
  the adopted candidate takes that factor instead (printed).

**The coverage shrink (2026-11-28; rule written down and committed before any candidate was
computed outside the calibration set and before any scan of fresh-cov).** The over-prediction
study above (its ``"outside-cap"`` was adopted by its rule but its wiring not merged:
it moved no held-out count) found, read after its decision, that the held-out
over-predictions are mostly the coverage term's: 56 of the 100 test and fresh scans more than
2x high and 24 of fresh-high's 33 have it as their largest part; easy rough plastics at the
default scan (true 0.003-0.013) read 0.028-0.041 because the coverage term alone is about 0.03.
What no pair looks at is only as wrong as the material is hard to predict between pairs, and a
designed layout (pairs chosen by the joint fit's expected error, which spreads them over the
table) says that through ``cv_log_error``, the readings' own leave-one-pair-out error in the
metric's units. The industrial presets (MA68, MA98) are left alone: their scans with a tiny
``cv_log_error`` are genuinely bad (their pairs sit where they predict each other, not where
the table's error is). Nothing of these forms has been computed on any set before this was
written.

* **Two forms, one parameter ``c`` each** (the shipped mapping otherwise: highlight and under
  terms, the misfit and peak floors; :func:`cov_candidate`). For a scan with a designed
  layout (a plan whose design is ``"posterior"``), the coverage term ``FINAL_COVERAGE_SCALE
  sqrt(uncovered)`` times ``s``: ``"cov-linear"``, ``s = min(1, cv_log_error / c)``;
  ``"cov-sqrt"``, ``s = min(1, sqrt(cv_log_error / c))``. Presets unchanged; a NaN
  ``cv_log_error`` leaves the term unchanged. ``c`` over 0.01-0.50 in steps of 0.01
  (:data:`COV_GRID`; ``c`` -> 0 is the shipped mapping).
* **Fit (calibration set only, 145 scans).** Over both grids: the fewest scans more than 2x
  low, then the most within x2, then ``"cov-linear"`` before ``"cov-sqrt"``, then the value
  nearer the shipped mapping (the smaller ``c``). No gain within x2 at no more low than the
  shipped estimate ends the study: not adopted.
* **Choice set (55 scans).** Adopted only if the candidate leaves no more choice scans more
  than 2x low than the shipped estimate and strictly more within x2.
* **Test and fresh sets** (test, fresh, fresh-inplane, fresh-confirm: 290 scans), printed once
  after the choice: adopted only if no more of them more than 2x low (within x2 reported).
* **fresh-wide, fresh-coat and fresh-high** (180 scans; looked at for earlier terms, so not
  blind): adopted only if no more of them more than 2x low.
* **fresh-cov** (60 scans, :data:`FRESH_COV`, written down with this rule and committed before
  any scan of them), scanned after the choice and printed last: adopted only if no more of
  them more than 2x low (within x2 reported, not a condition).
* **The interval.** As in the over-prediction study: the candidate's calibration p98 of
  ``true / estimate`` over the scans not flagged is printed; if it exceeds ``UPPER_FACTOR`` an
  adopted candidate takes that factor instead.
* **Wiring, if adopted.** ``reconstruct`` does not know whether a layout was designed; an
  adopted form needs the scan's plan to say so (a preset's cells are recognisable). Not
  decided here.

**The mirror gap (2026-11-29; rule written down and committed before any candidate was
computed on any set and before any scan of fresh-mirror).** Read before this rule (every set's
rows listed, so no set but fresh-mirror is blind to it): 18 of the 24 scans more than 2x low
over every set are the presets' (MA68, MA98) on glossy plastics, clear coats and smooth
metals (fresh-coat 10, fresh-wide 3, test 3, choice 1, fresh-cov 1), true 0.08-0.22 against
estimates of 0.02-0.07, with every witness of the readings small (``cv_log_error``
0.007-0.07). The presets read no pair nearer the mirror direction than ``th_h`` = 2.5 deg
(MA98) or 7.5 deg (MA68, BYK-mac, MultiFX10); the designed layouts put a pair on ``th_h`` = 0.
Rotating the specimen about its normal keeps every pair's ``th_h``, so no stage angle closes
that gap: a highlight narrower than it is unseen by construction, whatever the readings say,
and the estimate should carry it. The witness is the layout's **mirror gap** ``g``, the least
``th_h`` over its pairs in degrees (:func:`gonio.brdf.mirrorgap.cells_gap_deg`; a property
of the layout, not of the readings).

* **Two forms, one parameter ``m`` each** (``log_rmse`` units), added as a variance beside the
  coverage, highlight and under terms (``final_log_rmse(..., in_plane=term)``), under the
  misfit and peak floors (:func:`mirror_candidate`): ``"gap-step"``, ``term = m`` when ``g``
  > 1 deg (a pair within 1 deg counts as reading the mirror direction), else 0;
  ``"gap-sqrt"``, ``term = m min(1, sqrt(g / 7.5))``. ``m`` over 0.005-0.300 in steps of
  0.005 (:data:`MIRROR_GRID`; ``m`` = 0 is the shipped mapping). Designed layouts (``g`` = 0)
  are unchanged by either form.
* **Fit (calibration, fresh-wide and fresh-coat: 265 scans).** The calibration set has no
  preset scan more than 2x low, so it alone would choose nothing; fresh-wide and fresh-coat,
  where the blind spot was found, join it. Over both grids: the fewest scans more than 2x low,
  then the most within x2, then ``"gap-step"`` before ``"gap-sqrt"``, then the smaller ``m``.
  No fewer low than the shipped estimate there ends the study: not adopted.
* **Checks (not blind; each a condition):** choice; test, fresh, fresh-inplane and
  fresh-confirm; fresh-high and fresh-cov: no more scans more than 2x low than the shipped
  estimate in each group. Over every set before the blind one the share within x2 may fall by
  at most 5 percentage points (the price of a conservative estimate on the presets' matte
  scans is paid in over-predictions; more than that is not adopted).
* **fresh-mirror** (60 scans, :data:`FRESH_MIRROR`, written down with this rule and committed
  before any scan of them; glossy and matte materials as a lab meets them), scanned after the
  choice and printed last: adopted only if no more of them more than 2x low (within x2
  reported, not a condition).
* **The interval.** As in the studies above: the candidate's calibration p98 of ``true /
  estimate`` over the scans not flagged is printed; if it exceeds ``UPPER_FACTOR`` an adopted
  candidate takes that factor instead.
* **Wiring, if adopted.** ``reconstruct`` has the layout's cells, so the gap is computed there
  and the term joins the shipped mapping; the result says why the estimate is wide (the gap
  and what it cannot see).

Result (one run, 179 s with the rows of the earlier sets read from ``--rows``):
``"gap-step"``, ``m`` = 0.105 (fit set 155 / 19 -> 142 / 6 within x2 / more than 2x low).
Every check group passed (no more low: choice 1 -> 0, test and fresh 3 -> 0, fresh-high and
fresh-cov 1 -> 0), but over every set before the blind one the scans within x2 fell from 440
to 379 of 730 (8.4 points, above the 5-point slack): the presets' matte scans, whose estimates
were right, go more than 2x high (MA98 on fresh 15 -> 6 within x2). **Not adopted.** The blind
fresh-mirror: 38 / 5 -> 34 / 3 (the presets' two low scans mended; the other three are
``fm-white-plastic-r015`` at the designed plans, 2.8-3.1x low with a pair on the mirror
direction, the clear-coat pattern of fresh-coat that this term does not touch).

Before this round the choice and test sets were one validation set, whose numbers earlier
rounds printed while comparing forms; the test and fresh sets then decided whether the refit
chosen on the choice set replaced the shipped mapping (it did not). docs/science.md 7.1.1 says
which set saw what.

Printed: one table per plan (material, set, true ``log_rmse``, the estimate of the rejected
refit (:data:`REFIT_CANDIDATE`, from the same scan), its ratio, the shipped final mapping's
estimate, its ratio, within x2, more than 2x too low, the coverage
witness ``uncovered``, the misfit witness and whether the result carries the ``basis_misfit``
reason), then the shares within x2, the counts more than 2x low and the lowest ratio per set
and plan for both, how often the truth is above the interval's upper end, the scans
flagged per set and plan, what the scans more than 2x low show (their misfit; with
``--witnesses`` also their standardised leave-one-pair-out error), and the in-plane
candidate's fit, choice and one report (:func:`in_plane_study`, not adopted). Results:
docs/science.md 7.1.1.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import bench_asymmetric as ba  # sibling benches (the script's folder is on sys.path)
import bench_unseen as bu
import numpy as np

from gonio.brdf.design.presets import get_preset
from gonio.brdf.highlightread import EXCESS_LIMIT, highlight_read
from gonio.brdf.mirrorgap import MIRROR_GAP_LIMIT_DEG, cells_gap_deg
from gonio.brdf.reconstruction.basis import default_basis
from gonio.brdf.reconstruction.localprior import out_of_plane_share
from gonio.brdf.reconstruction.reconstruct import reconstruct
from gonio.brdf.reconstruction.samples import DEFAULT_SPAN_DEG, uniform_stage_angles
from gonio.brdf.reconstruction.selfcheck import (
    FINAL_COVERAGE_SCALE,
    FINAL_FLAGGED_FACTOR,
    FINAL_HIGHLIGHT_SCALE,
    FINAL_PREDICTED_FACTOR,
    FINAL_UNDER_SCALE,
    UPPER_FACTOR,
    UPPER_FACTOR_FLAGGED,
    UPPER_PERCENTILE,
    BasisMisfit,
    estimate_parts,
    final_log_rmse,
    highlight_term,
    under_term,
    upper_factor_from,
    widen_log_rmse,
)
from gonio.brdf.tables import metrics

#: The refit of the final mapping (factor on the model's estimate, coverage scale, factor on a
#: flagged scan's estimate; misfit floor as shipped) that the choice set preferred and the
#: test and fresh sets rejected (docs/science.md 7.1.1): the "refit" columns.
REFIT_CANDIDATE: tuple[float, float, float] = (0.80, 0.19, 0.55)


def row_misfit(row: dict[str, Any]) -> BasisMisfit:
    """The scan's basis misfit, from a row's numbers (flagged exactly when the scan's result
    carried the ``basis_misfit`` reason: checked in :func:`table`)."""
    return BasisMisfit(chi2=row["misfit_chi2"], log_misfit=row["misfit_log"],
                       persistent_pairs=int(row["misfit_persistent_pairs"]),
                       n_pairs=int(row["n"]), n_angles=int(row["r"]))


def peak_floor(row: dict[str, Any]) -> float:
    """The floor every estimate has under it (``reconstruct``: the error above the physical
    peak bound, science.md 7.5); 0 for rows written before it or without a positive reading."""
    v = float(row.get("peak_excess", 0.0))
    return v if np.isfinite(v) else 0.0


def refit_candidate(row: dict[str, Any]) -> float:
    """The rejected refit's ``predicted_log_rmse`` of a row (:data:`REFIT_CANDIDATE`): the
    shipped final mapping with the refit's constants, under the same floor as the shipped
    estimate."""
    k, c, kf = REFIT_CANDIDATE
    return max(final_log_rmse(row["unwidened"], row["uncovered"], row_misfit(row),
                              predicted_factor=k, coverage_scale=c, flagged_factor=kf),
               peak_floor(row))


#: ``(label, design, r)``: ``design`` is "posterior" (the default 10-pair design) or a preset.
PLANS: tuple[tuple[str, str, int], ...] = (
    ("default n=10 r=8", "posterior", 8),
    ("n=10 r=4", "posterior", 4),
    ("n=10 r=16", "posterior", 16),
    ("MA68 r=8", "MA68", 8),
    ("MA98 r=8", "MA98", 8),
)


#: The sets (module docstring): constants are fitted on "cal", forms are chosen on "choice",
#: "test" is reported once, after every choice, and "fresh" holds specimens no round had
#: seen before that report (:data:`FRESH`).
SETS: tuple[str, ...] = ("cal", "choice", "test", "fresh", "fresh-inplane", "fresh-confirm",
                         "fresh-wide", "fresh-coat", "fresh-high", "fresh-cov", "fresh-mirror")

#: Fresh mitsuba specimens ``(name, spec, holder angle in degrees, tilt in degrees, tilt
#: azimuth in degrees)``: added after the test set's one report, scanned once with the mapping
#: already chosen, and in no choice. Anisotropic conductors at new roughness pairs and holder
#: angles, plastics, layered clear-coated and sheen (satin-like) principled materials, a
#: blend, and four normal-mapped surfaces tilted like ``bench_asymmetric.ASYM`` (tilt 0: not
#: normal-mapped).
FRESH: tuple[tuple[str, dict[str, Any], float, float, float], ...] = (
    ("fr-cr-u05-v22", {"type": "roughconductor", "material": "Cr", "distribution": "ggx",
                       "alpha_u": 0.05, "alpha_v": 0.22}, 33.0, 0.0, 0.0),
    ("fr-al-u30-v10", {"type": "roughconductor", "material": "Al",
                       "distribution": "beckmann", "alpha_u": 0.30, "alpha_v": 0.10},
     151.0, 0.0, 0.0),
    ("fr-au-r18", {"type": "roughconductor", "material": "Au", "alpha": 0.18}, 0.0, 0.0, 0.0),
    ("fr-cu-u15-v45", {"type": "roughconductor", "material": "Cu", "distribution": "ggx",
                       "alpha_u": 0.15, "alpha_v": 0.45}, 242.0, 0.0, 0.0),
    ("fr-ag-r04", {"type": "roughconductor", "material": "Ag", "alpha": 0.04}, 0.0, 0.0, 0.0),
    ("fr-green-plastic-r05", {"type": "roughplastic", "alpha": 0.05, "diffuse_reflectance": {
        "type": "rgb", "value": [0.1, 0.45, 0.15]}}, 12.0, 0.0, 0.0),
    ("fr-white-plastic-r30", {"type": "roughplastic", "alpha": 0.30, "diffuse_reflectance": {
        "type": "rgb", "value": [0.8, 0.8, 0.78]}}, 77.0, 0.0, 0.0),
    ("fr-paper-r45", {"type": "roughplastic", "alpha": 0.45, "diffuse_reflectance": {
        "type": "rgb", "value": [0.85, 0.84, 0.8]}}, 0.0, 0.0, 0.0),
    ("fr-clearcoat-red", {"type": "principled", "roughness": 0.5, "clearcoat": 1.0,
                          "clearcoat_gloss": 0.9, "base_color": {
                              "type": "rgb", "value": [0.6, 0.05, 0.05]}}, 120.0, 0.0, 0.0),
    ("fr-clearcoat-brushed", {"type": "principled", "metallic": 1.0, "roughness": 0.3,
                              "anisotropic": 0.5, "clearcoat": 0.8, "base_color": {
                                  "type": "rgb", "value": [0.7, 0.7, 0.75]}}, 200.0, 0.0, 0.0),
    ("fr-sheen-satin", {"type": "principled", "roughness": 0.6, "sheen": 1.0, "base_color": {
        "type": "rgb", "value": [0.5, 0.3, 0.6]}}, 45.0, 0.0, 0.0),
    ("fr-blend-brushed-cr", {"type": "blendbsdf", "weight": 0.5,
                             "bsdf_0": {"type": "diffuse", "reflectance": {
                                 "type": "rgb", "value": [0.3, 0.3, 0.35]}},
                             "bsdf_1": {"type": "roughconductor", "material": "Cr",
                                        "alpha_u": 0.07, "alpha_v": 0.4}}, 288.0, 0.0, 0.0),
    ("fr-tilt-cr-t12", {"type": "roughconductor", "material": "Cr", "alpha": 0.12},
     95.0, 12.0, 60.0),
    ("fr-tilt-green-plastic-t18", {"type": "roughplastic", "alpha": 0.15,
                                   "diffuse_reflectance": {
                                       "type": "rgb", "value": [0.1, 0.45, 0.15]}},
     170.0, 18.0, 250.0),
    ("fr-tilt-au-aniso-t8", {"type": "roughconductor", "material": "Au", "alpha_u": 0.1,
                             "alpha_v": 0.3}, 15.0, 8.0, 330.0),
    ("fr-tilt-white-plastic-t25", {"type": "roughplastic", "alpha": 0.3,
                                   "diffuse_reflectance": {
                                       "type": "rgb", "value": [0.8, 0.8, 0.78]}},
     260.0, 25.0, 140.0),
)


#: A third set of fresh mitsuba specimens, written down on 2026-11-27 together with the
#: in-plane candidate and its rule (:func:`in_plane_study`) and before any scan of them: the
#: blind test of that candidate, scanned once. Glossy and anisotropic conductors (one below
#: the library's roughest-smooth alpha 0.05), a black and two coloured rough plastics, a
#: satin, an anisotropic gold and a clear-coated metallic principled material, two blends and
#: a white diffuse, and two normal-mapped surfaces.
FRESH_INPLANE: tuple[tuple[str, dict[str, Any], float, float, float], ...] = (
    ("f3-ag-u10-v30", {"type": "roughconductor", "material": "Ag", "distribution": "ggx",
                       "alpha_u": 0.10, "alpha_v": 0.30}, 71.0, 0.0, 0.0),
    ("f3-cr-r08", {"type": "roughconductor", "material": "Cr", "alpha": 0.08}, 0.0, 0.0, 0.0),
    ("f3-au-u04-v12", {"type": "roughconductor", "material": "Au", "distribution": "ggx",
                       "alpha_u": 0.04, "alpha_v": 0.12}, 203.0, 0.0, 0.0),
    ("f3-al-r03", {"type": "roughconductor", "material": "Al", "distribution": "ggx",
                   "alpha": 0.03}, 0.0, 0.0, 0.0),
    ("f3-cu-r12", {"type": "roughconductor", "material": "Cu", "distribution": "ggx",
                   "alpha": 0.12}, 0.0, 0.0, 0.0),
    ("f3-black-plastic-r08", {"type": "roughplastic", "alpha": 0.08, "diffuse_reflectance": {
        "type": "rgb", "value": [0.03, 0.03, 0.03]}}, 0.0, 0.0, 0.0),
    ("f3-yellow-plastic-r15", {"type": "roughplastic", "alpha": 0.15, "diffuse_reflectance": {
        "type": "rgb", "value": [0.7, 0.6, 0.1]}}, 0.0, 0.0, 0.0),
    ("f3-grey-plastic-r60", {"type": "roughplastic", "alpha": 0.6, "diffuse_reflectance": {
        "type": "rgb", "value": [0.4, 0.4, 0.4]}}, 0.0, 0.0, 0.0),
    ("f3-satin", {"type": "principled", "roughness": 0.45, "specular": 0.3, "sheen": 0.5,
                  "base_color": {"type": "rgb", "value": [0.2, 0.4, 0.7]}}, 33.0, 0.0, 0.0),
    ("f3-brushed-gold", {"type": "principled", "metallic": 1.0, "roughness": 0.25,
                         "anisotropic": 0.9, "base_color": {
                             "type": "rgb", "value": [0.9, 0.7, 0.3]}}, 148.0, 0.0, 0.0),
    ("f3-clearcoat-blue-metallic", {"type": "principled", "metallic": 0.7, "roughness": 0.4,
                                    "clearcoat": 1.0, "clearcoat_gloss": 0.95, "base_color": {
                                        "type": "rgb", "value": [0.1, 0.2, 0.6]}},
     0.0, 0.0, 0.0),
    ("f3-blend-diffuse-au", {"type": "blendbsdf", "weight": 0.4,
                             "bsdf_0": {"type": "diffuse", "reflectance": {
                                 "type": "rgb", "value": [0.6, 0.6, 0.55]}},
                             "bsdf_1": {"type": "roughconductor", "material": "Au",
                                        "alpha": 0.05}}, 0.0, 0.0, 0.0),
    ("f3-blend-brushed-ag", {"type": "blendbsdf", "weight": 0.5,
                             "bsdf_0": {"type": "diffuse", "reflectance": {
                                 "type": "rgb", "value": [0.1, 0.1, 0.3]}},
                             "bsdf_1": {"type": "roughconductor", "material": "Ag",
                                        "alpha_u": 0.05, "alpha_v": 0.25}}, 256.0, 0.0, 0.0),
    ("f3-diffuse-white", {"type": "diffuse", "reflectance": {
        "type": "rgb", "value": [0.85, 0.85, 0.85]}}, 0.0, 0.0, 0.0),
    ("f3-tilt-ag-t20", {"type": "roughconductor", "material": "Ag", "alpha": 0.15},
     40.0, 20.0, 200.0),
    ("f3-tilt-red-plastic-t10", {"type": "roughplastic", "alpha": 0.2, "diffuse_reflectance": {
        "type": "rgb", "value": [0.6, 0.1, 0.1]}}, 12.0, 10.0, 300.0),
)


#: A fourth set of fresh mitsuba specimens, written down on 2026-11-27 with the in-plane
#: candidate's confirmation rule (:func:`confirm_in_plane`) and before any scan of them: its
#: blind set, scanned once. New conductors (Rh, Mo, W, TiN, Ta; glossy, rough, anisotropic),
#: glossy to rough coloured plastics, principled glossy, metallic clear-coated, satin and
#: brushed materials, a blend, a grey diffuse, and two normal-mapped surfaces.
FRESH_CONFIRM: tuple[tuple[str, dict[str, Any], float, float, float], ...] = (
    ("f5-rh-r06", {"type": "roughconductor", "material": "Rh", "alpha": 0.06},
     0.0, 0.0, 0.0),
    ("f5-mo-u08-v35", {"type": "roughconductor", "material": "Mo", "distribution": "ggx",
                       "alpha_u": 0.08, "alpha_v": 0.35}, 57.0, 0.0, 0.0),
    ("f5-w-r20", {"type": "roughconductor", "material": "W", "distribution": "beckmann",
                  "alpha": 0.20}, 0.0, 0.0, 0.0),
    ("f5-tin-r10", {"type": "roughconductor", "material": "TiN", "alpha": 0.10},
     0.0, 0.0, 0.0),
    ("f5-ta-u25-v06", {"type": "roughconductor", "material": "Ta", "distribution": "ggx",
                       "alpha_u": 0.25, "alpha_v": 0.06}, 118.0, 0.0, 0.0),
    ("f5-orange-plastic-r07", {"type": "roughplastic", "alpha": 0.07, "diffuse_reflectance": {
        "type": "rgb", "value": [0.8, 0.35, 0.05]}}, 0.0, 0.0, 0.0),
    ("f5-navy-plastic-r20", {"type": "roughplastic", "distribution": "beckmann", "alpha": 0.2,
                             "diffuse_reflectance": {"type": "rgb",
                                                     "value": [0.05, 0.08, 0.3]}},
     0.0, 0.0, 0.0),
    ("f5-ivory-plastic-r40", {"type": "roughplastic", "alpha": 0.4, "diffuse_reflectance": {
        "type": "rgb", "value": [0.8, 0.75, 0.6]}}, 0.0, 0.0, 0.0),
    ("f5-glossy-green", {"type": "principled", "roughness": 0.15, "specular": 0.5,
                         "base_color": {"type": "rgb", "value": [0.1, 0.5, 0.2]}},
     0.0, 0.0, 0.0),
    ("f5-metallic-red-coat", {"type": "principled", "metallic": 0.8, "roughness": 0.3,
                              "clearcoat": 0.5, "base_color": {
                                  "type": "rgb", "value": [0.7, 0.1, 0.1]}}, 0.0, 0.0, 0.0),
    ("f5-satin-grey", {"type": "principled", "roughness": 0.55, "sheen": 0.6,
                       "specular": 0.4, "base_color": {"type": "rgb",
                                                       "value": [0.5, 0.5, 0.5]}},
     0.0, 0.0, 0.0),
    ("f5-brushed-copper", {"type": "principled", "metallic": 1.0, "roughness": 0.35,
                           "anisotropic": 0.7, "base_color": {
                               "type": "rgb", "value": [0.9, 0.5, 0.3]}}, 305.0, 0.0, 0.0),
    ("f5-blend-diffuse-mo", {"type": "blendbsdf", "weight": 0.3,
                             "bsdf_0": {"type": "diffuse", "reflectance": {
                                 "type": "rgb", "value": [0.5, 0.45, 0.4]}},
                             "bsdf_1": {"type": "roughconductor", "material": "Mo",
                                        "alpha": 0.08}}, 0.0, 0.0, 0.0),
    ("f5-diffuse-grey", {"type": "diffuse", "reflectance": {
        "type": "rgb", "value": [0.3, 0.3, 0.3]}}, 0.0, 0.0, 0.0),
    ("f5-tilt-rh-t15", {"type": "roughconductor", "material": "Rh", "alpha": 0.12},
     210.0, 15.0, 80.0),
    ("f5-tilt-orange-plastic-t12", {"type": "roughplastic", "alpha": 0.12,
                                    "diffuse_reflectance": {
                                        "type": "rgb", "value": [0.8, 0.35, 0.05]}},
     33.0, 12.0, 170.0),
)


#: A fifth set of fresh mitsuba specimens, written down on 2026-11-28 with the highlight
#: widening's rule (:func:`highlight_study`) and committed before any scan of them: its blind
#: set, scanned once and reported last. Conductors no set has held (Ir, Nb, Ni, V, Be, TiC;
#: glossy to rough, two anisotropic at holder angles), glossy to rough coloured plastics,
#: clear-coated principled materials (white, black, a metallic green turned in the holder) and
#: a tilted normal-mapped niobium.
FRESH_WIDE: tuple[tuple[str, dict[str, Any], float, float, float], ...] = (
    ("f6-ir-r05", {"type": "roughconductor", "material": "Ir", "alpha": 0.05},
     0.0, 0.0, 0.0),
    ("f6-nb-u06-v20", {"type": "roughconductor", "material": "Nb", "distribution": "ggx",
                       "alpha_u": 0.06, "alpha_v": 0.20}, 134.0, 0.0, 0.0),
    ("f6-ni-r15", {"type": "roughconductor", "material": "Ni_palik",
                   "distribution": "beckmann", "alpha": 0.15}, 0.0, 0.0, 0.0),
    ("f6-v-u30-v08", {"type": "roughconductor", "material": "V_palik", "distribution": "ggx",
                      "alpha_u": 0.30, "alpha_v": 0.08}, 221.0, 0.0, 0.0),
    ("f6-be-r25", {"type": "roughconductor", "material": "Be", "alpha": 0.25},
     0.0, 0.0, 0.0),
    ("f6-tic-r09", {"type": "roughconductor", "material": "TiC", "distribution": "ggx",
                    "alpha": 0.09}, 0.0, 0.0, 0.0),
    ("f6-magenta-plastic-r04", {"type": "roughplastic", "alpha": 0.04,
                                "diffuse_reflectance": {"type": "rgb",
                                                        "value": [0.6, 0.05, 0.4]}},
     0.0, 0.0, 0.0),
    ("f6-teal-plastic-r12", {"type": "roughplastic", "distribution": "beckmann",
                             "alpha": 0.12, "diffuse_reflectance": {
                                 "type": "rgb", "value": [0.05, 0.4, 0.4]}}, 0.0, 0.0, 0.0),
    ("f6-clearcoat-white", {"type": "principled", "roughness": 0.6, "clearcoat": 1.0,
                            "clearcoat_gloss": 1.0, "base_color": {
                                "type": "rgb", "value": [0.8, 0.8, 0.8]}}, 0.0, 0.0, 0.0),
    ("f6-clearcoat-black", {"type": "principled", "roughness": 0.3, "clearcoat": 1.0,
                            "clearcoat_gloss": 0.8, "base_color": {
                                "type": "rgb", "value": [0.02, 0.02, 0.02]}}, 0.0, 0.0, 0.0),
    ("f6-clearcoat-green-metallic", {"type": "principled", "metallic": 0.6, "roughness": 0.35,
                                     "anisotropic": 0.4, "clearcoat": 1.0,
                                     "clearcoat_gloss": 0.9, "base_color": {
                                         "type": "rgb", "value": [0.1, 0.5, 0.2]}},
     72.0, 0.0, 0.0),
    ("f6-tilt-nb-t10", {"type": "roughconductor", "material": "Nb", "alpha": 0.10},
     300.0, 10.0, 120.0),
)

#: A sixth set of fresh mitsuba specimens, written down on 2026-11-28 with the rule of the
#: leave-one-pair-out under-prediction term (:func:`under_study`) and committed before any scan
#: of them: its blind set. Half of them carry the structure of ``f6-clearcoat-white`` (a sharp
#: coat or mirror peak over a diffuse body: principled clear coats of several glosses and
#: bodies, smooth plastics at alpha 0.01-0.02), the rest are controls (a smooth and a brushed
#: conductor, a rough white plastic, a blend, a matte clear coat).
FRESH_COAT: tuple[tuple[str, dict[str, Any], float, float, float], ...] = (
    ("f7-clearcoat-ivory", {"type": "principled", "roughness": 0.5, "clearcoat": 1.0,
                            "clearcoat_gloss": 0.95, "base_color": {
                                "type": "rgb", "value": [0.85, 0.8, 0.65]}}, 0.0, 0.0, 0.0),
    ("f7-clearcoat-grey", {"type": "principled", "roughness": 0.7, "clearcoat": 0.6,
                           "clearcoat_gloss": 1.0, "base_color": {
                               "type": "rgb", "value": [0.4, 0.4, 0.4]}}, 0.0, 0.0, 0.0),
    ("f7-clearcoat-blue", {"type": "principled", "roughness": 0.4, "clearcoat": 1.0,
                           "clearcoat_gloss": 0.7, "base_color": {
                               "type": "rgb", "value": [0.1, 0.2, 0.6]}}, 0.0, 0.0, 0.0),
    ("f7-clearcoat-white-gloss", {"type": "principled", "roughness": 0.2, "clearcoat": 0.8,
                                  "clearcoat_gloss": 1.0, "base_color": {
                                      "type": "rgb", "value": [0.9, 0.9, 0.9]}},
     0.0, 0.0, 0.0),
    ("f7-clearcoat-yellow", {"type": "principled", "roughness": 0.6, "clearcoat": 1.0,
                             "clearcoat_gloss": 0.85, "anisotropic": 0.3, "base_color": {
                                 "type": "rgb", "value": [0.8, 0.6, 0.1]}}, 40.0, 0.0, 0.0),
    ("f7-clearcoat-matte", {"type": "principled", "roughness": 0.8, "clearcoat": 1.0,
                            "clearcoat_gloss": 0.2, "base_color": {
                                "type": "rgb", "value": [0.6, 0.6, 0.6]}}, 0.0, 0.0, 0.0),
    ("f7-white-plastic-r01", {"type": "roughplastic", "alpha": 0.01, "diffuse_reflectance": {
        "type": "rgb", "value": [0.75, 0.75, 0.75]}}, 0.0, 0.0, 0.0),
    ("f7-red-plastic-r02", {"type": "roughplastic", "distribution": "beckmann", "alpha": 0.02,
                            "diffuse_reflectance": {"type": "rgb",
                                                    "value": [0.6, 0.1, 0.1]}}, 0.0, 0.0, 0.0),
    ("f7-al-r02", {"type": "roughconductor", "material": "Al", "alpha": 0.02},
     0.0, 0.0, 0.0),
    ("f7-cr-u04-v18", {"type": "roughconductor", "material": "Cr", "distribution": "ggx",
                       "alpha_u": 0.04, "alpha_v": 0.18}, 95.0, 0.0, 0.0),
    ("f7-white-plastic-r35", {"type": "roughplastic", "alpha": 0.35, "diffuse_reflectance": {
        "type": "rgb", "value": [0.7, 0.7, 0.7]}}, 0.0, 0.0, 0.0),
    ("f7-blend-white-au", {"type": "blendbsdf", "weight": 0.3,
                           "bsdf_0": {"type": "diffuse", "reflectance": {
                               "type": "rgb", "value": [0.7, 0.7, 0.7]}},
                           "bsdf_1": {"type": "roughconductor", "material": "Au",
                                      "alpha": 0.03}}, 0.0, 0.0, 0.0),
)


#: A seventh set of fresh mitsuba specimens, written down on 2026-11-28 with the rule of the
#: over-prediction study (:func:`high_study`) and committed before any scan of them: its blind
#: set, scanned once and reported last. Conductors no set has held (Hg, VC, CuO, Li; a
#: near-mirror, an anisotropic pair at a holder angle, a rough dark oxide), rough to glossy
#: plastics of new colours, a dark red diffuse, rough and anisotropic-specular principled
#: materials, a rough-plastic / brushed-chromium blend, and a tilted normal-mapped plastic.
FRESH_HIGH: tuple[tuple[str, dict[str, Any], float, float, float], ...] = (
    ("fh-hg-r02", {"type": "roughconductor", "material": "Hg", "alpha": 0.02},
     0.0, 0.0, 0.0),
    ("fh-vc-u12-v40", {"type": "roughconductor", "material": "VC", "distribution": "ggx",
                       "alpha_u": 0.12, "alpha_v": 0.40}, 17.0, 0.0, 0.0),
    ("fh-cuo-r35", {"type": "roughconductor", "material": "CuO",
                    "distribution": "beckmann", "alpha": 0.35}, 0.0, 0.0, 0.0),
    ("fh-li-r07", {"type": "roughconductor", "material": "Li", "alpha": 0.07},
     0.0, 0.0, 0.0),
    ("fh-purple-plastic-r25", {"type": "roughplastic", "alpha": 0.25, "diffuse_reflectance": {
        "type": "rgb", "value": [0.35, 0.1, 0.45]}}, 0.0, 0.0, 0.0),
    ("fh-beige-plastic-r50", {"type": "roughplastic", "distribution": "beckmann",
                              "alpha": 0.5, "diffuse_reflectance": {
                                  "type": "rgb", "value": [0.7, 0.6, 0.45]}}, 0.0, 0.0, 0.0),
    ("fh-cyan-plastic-r09", {"type": "roughplastic", "alpha": 0.09, "diffuse_reflectance": {
        "type": "rgb", "value": [0.1, 0.6, 0.7]}}, 0.0, 0.0, 0.0),
    ("fh-diffuse-dark-red", {"type": "diffuse", "reflectance": {
        "type": "rgb", "value": [0.25, 0.04, 0.04]}}, 0.0, 0.0, 0.0),
    ("fh-rough-metal", {"type": "principled", "metallic": 1.0, "roughness": 0.7,
                        "base_color": {"type": "rgb", "value": [0.6, 0.6, 0.55]}},
     0.0, 0.0, 0.0),
    ("fh-aniso-specular-green", {"type": "principled", "roughness": 0.35, "specular": 0.8,
                                 "sheen": 0.3, "anisotropic": 0.6, "base_color": {
                                     "type": "rgb", "value": [0.2, 0.6, 0.3]}},
     250.0, 0.0, 0.0),
    ("fh-blend-plastic-cr", {"type": "blendbsdf", "weight": 0.6,
                             "bsdf_0": {"type": "roughplastic", "alpha": 0.3,
                                        "diffuse_reflectance": {
                                            "type": "rgb", "value": [0.8, 0.8, 0.8]}},
                             "bsdf_1": {"type": "roughconductor", "material": "Cr",
                                        "alpha_u": 0.2, "alpha_v": 0.05}}, 160.0, 0.0, 0.0),
    ("fh-tilt-purple-plastic-t20", {"type": "roughplastic", "alpha": 0.25,
                                    "diffuse_reflectance": {
                                        "type": "rgb", "value": [0.35, 0.1, 0.45]}},
     110.0, 20.0, 30.0),
)


#: An eighth set of fresh mitsuba specimens, written down on 2026-11-28 with the rule of the
#: coverage shrink (:func:`cov_study`) and committed before any scan of them: its blind set,
#: scanned after the choice and reported last. Conductors no set has held (Cu2O, SiC, HgTe,
#: Na), roughness pairs and holder angles no set has used, plastics of new colours and
#: roughnesses, a sand diffuse, a rough orange clear coat, a sheen-heavy teal principled
#: material, a rough-plastic / brushed-tantalum blend and a tilted olive plastic.
FRESH_COV: tuple[tuple[str, dict[str, Any], float, float, float], ...] = (
    ("fc-cu2o-r14", {"type": "roughconductor", "material": "Cu2O", "alpha": 0.14},
     0.0, 0.0, 0.0),
    ("fc-sic-u09-v28", {"type": "roughconductor", "material": "SiC", "distribution": "ggx",
                        "alpha_u": 0.09, "alpha_v": 0.28}, 63.0, 0.0, 0.0),
    ("fc-hgte-r30", {"type": "roughconductor", "material": "HgTe",
                     "distribution": "beckmann", "alpha": 0.30}, 0.0, 0.0, 0.0),
    ("fc-na-r05", {"type": "roughconductor", "material": "Na_palik", "alpha": 0.05},
     0.0, 0.0, 0.0),
    ("fc-olive-plastic-r18", {"type": "roughplastic", "alpha": 0.18, "diffuse_reflectance": {
        "type": "rgb", "value": [0.4, 0.45, 0.15]}}, 0.0, 0.0, 0.0),
    ("fc-pink-plastic-r38", {"type": "roughplastic", "distribution": "beckmann",
                             "alpha": 0.38, "diffuse_reflectance": {
                                 "type": "rgb", "value": [0.8, 0.45, 0.5]}}, 0.0, 0.0, 0.0),
    ("fc-slate-plastic-r11", {"type": "roughplastic", "alpha": 0.11, "diffuse_reflectance": {
        "type": "rgb", "value": [0.2, 0.25, 0.3]}}, 0.0, 0.0, 0.0),
    ("fc-diffuse-sand", {"type": "diffuse", "reflectance": {
        "type": "rgb", "value": [0.6, 0.5, 0.35]}}, 0.0, 0.0, 0.0),
    ("fc-clearcoat-orange-rough", {"type": "principled", "roughness": 0.75, "clearcoat": 0.7,
                                   "clearcoat_gloss": 0.6, "base_color": {
                                       "type": "rgb", "value": [0.85, 0.4, 0.1]}},
     0.0, 0.0, 0.0),
    ("fc-sheen-teal", {"type": "principled", "roughness": 0.5, "sheen": 0.8,
                       "sheen_tint": 0.5, "base_color": {
                           "type": "rgb", "value": [0.1, 0.45, 0.45]}}, 0.0, 0.0, 0.0),
    ("fc-blend-plastic-ta", {"type": "blendbsdf", "weight": 0.5,
                             "bsdf_0": {"type": "roughplastic", "alpha": 0.22,
                                        "diffuse_reflectance": {
                                            "type": "rgb", "value": [0.55, 0.65, 0.8]}},
                             "bsdf_1": {"type": "roughconductor", "material": "Ta",
                                        "alpha_u": 0.07, "alpha_v": 0.25}}, 227.0, 0.0, 0.0),
    ("fc-tilt-olive-plastic-t14", {"type": "roughplastic", "alpha": 0.18,
                                   "diffuse_reflectance": {
                                       "type": "rgb", "value": [0.4, 0.45, 0.15]}},
     187.0, 14.0, 75.0),
)


#: A ninth set of fresh mitsuba specimens, written down on 2026-11-29 with the rule of the
#: mirror gap (:func:`mirror_study`) and committed before any scan of them: its blind set,
#: scanned after the choice and reported last. Glossy and matte materials as a lab meets them:
#: smooth plastics (white, blue, black), high-gloss clear coats over beige and red bases,
#: smooth Mo and TiN, a rough green plastic, a grey diffuse, a brushed Mo at holder 41 deg, a
#: matte lilac principled material and a glossy cream plastic / gold blend.
def _rgb(r: float, g: float, b: float) -> dict[str, Any]:
    """A mitsuba RGB colour of linear sRGB values."""
    return {"type": "rgb", "value": [r, g, b]}


def _plastic(alpha: float, colour: dict[str, Any], **more: Any) -> dict[str, Any]:
    """A mitsuba rough plastic of roughness ``alpha`` over a diffuse ``colour``."""
    return {"type": "roughplastic", **more, "alpha": alpha, "diffuse_reflectance": colour}


def _clearcoat(roughness: float, coat: float, gloss: float,
               colour: dict[str, Any]) -> dict[str, Any]:
    """A mitsuba principled base of ``roughness`` under a clear coat of weight ``coat``."""
    return {"type": "principled", "roughness": roughness, "clearcoat": coat,
            "clearcoat_gloss": gloss, "base_color": colour}


FRESH_MIRROR: tuple[tuple[str, dict[str, Any], float, float, float], ...] = (
    ("fm-white-plastic-r015", _plastic(0.015, _rgb(0.85, 0.85, 0.82)), 0.0, 0.0, 0.0),
    ("fm-blue-plastic-r03", _plastic(0.03, _rgb(0.1, 0.2, 0.6)), 0.0, 0.0, 0.0),
    ("fm-black-plastic-r02", _plastic(0.02, _rgb(0.03, 0.03, 0.03), distribution="beckmann"),
     0.0, 0.0, 0.0),
    ("fm-clearcoat-beige-gloss", _clearcoat(0.4, 1.0, 0.95, _rgb(0.8, 0.7, 0.55)),
     0.0, 0.0, 0.0),
    ("fm-clearcoat-red-gloss", _clearcoat(0.3, 0.9, 0.9, _rgb(0.6, 0.08, 0.06)), 0.0, 0.0, 0.0),
    ("fm-mo-r03", {"type": "roughconductor", "material": "Mo", "alpha": 0.03}, 0.0, 0.0, 0.0),
    ("fm-tin-r06", {"type": "roughconductor", "material": "TiN", "alpha": 0.06},
     0.0, 0.0, 0.0),
    ("fm-green-plastic-r25", _plastic(0.25, _rgb(0.15, 0.5, 0.2)), 0.0, 0.0, 0.0),
    ("fm-diffuse-grey", {"type": "diffuse", "reflectance": _rgb(0.45, 0.45, 0.45)},
     0.0, 0.0, 0.0),
    ("fm-mo-u20-v45", {"type": "roughconductor", "material": "Mo", "distribution": "ggx",
                       "alpha_u": 0.20, "alpha_v": 0.45}, 41.0, 0.0, 0.0),
    ("fm-principled-matte-lilac", {"type": "principled", "roughness": 0.8, "specular": 0.3,
                                   "base_color": _rgb(0.6, 0.5, 0.75)}, 0.0, 0.0, 0.0),
    ("fm-blend-cream-au", {"type": "blendbsdf", "weight": 0.3,
                           "bsdf_0": _plastic(0.04, _rgb(0.9, 0.85, 0.7)),
                           "bsdf_1": {"type": "roughconductor", "material": "Au",
                                      "alpha": 0.10}}, 0.0, 0.0, 0.0),
)


def fresh_materials(specimens: tuple[tuple[str, dict[str, Any], float, float, float], ...]
                    = FRESH, kind: str = "fresh") -> list[tuple[bu.Material, str]]:
    """``(material, kind)`` of ``specimens`` (:data:`FRESH` by default): kind ``kind``, or
    ``kind + "-tilted"`` for the normal-mapped ones."""
    out = []
    for name, inner, holder, tilt, azimuth in specimens:
        spec = ba.normalmap_spec(tilt, azimuth, inner) if tilt else inner
        m = ba.specimen(name, spec, holder, repr((inner, holder, tilt, azimuth)))
        out.append((m, f"{kind}-tilted" if tilt else kind))
    return out


def calibration_set(kind: str, index: int) -> bool:
    """True for the calibration materials (module docstring): ``index`` counts within the
    measured materials only."""
    return which_set(kind, index) == "cal"


def which_set(kind: str, index: int) -> str:
    """The set of a material (:data:`SETS`): ``index`` counts within its kind (for the tilted
    and untilted specimens, within ``bench_asymmetric.ASYM``, so a specimen and its untilted
    version are always in the same set).

    The calibration set is the previous rounds'. Their validation set is split in two: the
    measured materials at positions 1, 5, 9 and the specimens at even positions choose; the
    measured materials at positions 3, 7 and the specimens at odd positions test."""
    if kind in ("aniso-mitsuba", "library-asym"):
        return "cal"
    if kind == "measured":
        return "cal" if index % 2 == 0 else ("choice" if index % 4 == 1 else "test")
    return "choice" if index % 2 == 0 else "test"


def materials() -> list[tuple[bu.Material, str, str]]:
    """``(material, kind, set)`` of every held-out material (:func:`which_set`)."""
    out: list[tuple[bu.Material, str, str]] = []
    measured = bu.measured_materials() if bu.RGL_DIR.is_dir() else []
    out += [(m, "measured", which_set("measured", i)) for i, m in enumerate(measured)]
    out += [(m, "aniso-mitsuba", "cal") for m in bu.aniso_materials()]
    out += [(m, "asymmetric", which_set("asymmetric", i))
            for i, m in enumerate(ba.asym_materials())]
    out += [(m, "untilted", which_set("untilted", i))
            for i, m in enumerate(ba.asym_materials(tilted=False))]
    out += [(m, "library-asym", "cal") for m in library_asymmetric()]
    out += [(m, kind, "fresh") for m, kind in fresh_materials()]
    out += [(m, kind, "fresh-inplane")
            for m, kind in fresh_materials(FRESH_INPLANE, "fresh-inplane")]
    out += [(m, kind, "fresh-confirm")
            for m, kind in fresh_materials(FRESH_CONFIRM, "fresh-confirm")]
    out += [(m, kind, "fresh-wide")
            for m, kind in fresh_materials(FRESH_WIDE, "fresh-wide")]
    out += [(m, kind, "fresh-coat")
            for m, kind in fresh_materials(FRESH_COAT, "fresh-coat")]
    out += [(m, kind, "fresh-high")
            for m, kind in fresh_materials(FRESH_HIGH, "fresh-high")]
    out += [(m, kind, "fresh-cov")
            for m, kind in fresh_materials(FRESH_COV, "fresh-cov")]
    out += [(m, kind, "fresh-mirror")
            for m, kind in fresh_materials(FRESH_MIRROR, "fresh-mirror")]
    return out


#: Every how-many-th material of the library's families without twofold symmetry is taken
#: (:func:`library_asymmetric`).
ASYM_STRIDE = 4


def library_asymmetric() -> list[bu.Material]:
    """Every :data:`ASYM_STRIDE`-th material of the library's families without twofold symmetry
    (``library_specs(asymmetric=True)`` beyond ``library_specs()``): none of them is in the
    default basis, which holds only twofold-symmetric families. Calibration only."""
    from gonio.brdf.materials import library
    from gonio.brdf.models import analytic as bm
    from gonio.brdf.tables import geometry as geo

    plain = {s.name for s in library.library_specs()}
    specs = [s for s in library.library_specs(asymmetric=True) if s.name not in plain]
    out = []
    for s in specs[::ASYM_STRIDE]:
        vals = bu._cached(f"libasym-{s.name}", lambda s=s: np.asarray(
            bm.tabulate_valid(s.model), dtype=np.float32))
        if vals.shape[1] == 1:
            vals = np.repeat(vals, geo.N_PH, axis=1)
        out.append(bu.Material(s.name, "aniso", bu._full_table(vals, s.name), s.model, ()))
    return out


def scans(witnesses: bool = False, eta: float | None = None,
          sets: tuple[str, ...] | None = None) -> list[dict[str, Any]]:
    """One row per material and plan: the truth and every input of the estimate; with
    ``witnesses``, also ``calibrate_log_rmse.witnesses``' standardised leave-one-pair-out
    error ``z_loo_pair`` and the posterior's scale ``s2`` (one more fit per scan); ``eta``
    overrides the joint fit's (None: the default, ``reconstruct``'s); ``sets``: only the
    materials of these sets (None: every set), each read with the same seed as in a full
    run."""
    bu.CHOOSE["objective"] = "posterior"
    bu.SPAN["scan"] = bu.SPAN["design"] = DEFAULT_SPAN_DEG
    rows = []
    t0 = time.perf_counter()
    for i, (m, kind, which) in enumerate(materials()):
        if sets is not None and which not in sets:
            continue
        b = default_basis(exclude=m.exclude)
        for label, design, r in PLANS:
            cells, ph = bu.design(b, 10) if design == "posterior" else get_preset(design).cells()
            alpha = uniform_stage_angles(r, span=np.deg2rad(DEFAULT_SPAN_DEG))
            vals = bu.read(m, cells, ph, alpha, 100 + i)
            rec = reconstruct(b, cells, ph, alpha, vals, eta=eta)
            angle_err = (np.asarray(rec.angle_log_errors) if rec.angle_log_errors is not None
                         else np.full(r, np.nan))
            pair_err = (np.asarray(rec.pair_log_errors) if rec.pair_log_errors is not None
                        else np.full(len(cells), np.nan))
            rows.append({
                "material": m.name, "kind": kind, "cal": which == "cal", "set": which,
                "plan": label, "n": len(cells), "r": int(r),
                "truth": metrics.log_rmse(rec.table, m.truth),
                # The two-term model widened by a flagged misfit (two releases ago); after:
                # the final mapping (selfcheck.final_log_rmse) and its interval's upper end.
                "predicted": (widen_log_rmse(rec.predicted_log_rmse_unwidened, rec.misfit)
                              if rec.misfit is not None else rec.predicted_log_rmse_unwidened),
                "widened": rec.predicted_log_rmse,
                "upper": rec.predicted_log_rmse_upper,
                "uncovered": rec.uncovered_share,
                # The inputs of the mapping, so that candidates can be refitted on these rows.
                "unwidened": rec.predicted_log_rmse_unwidened,
                "expected": rec.expected_log_rmse, "mahalanobis": rec.mahalanobis,
                "cv_sample_error": rec.cv_sample_error, "cv_log_error": rec.cv_log_error,
                "cv_log_under": rec.cv_log_under,
                "angle_log_rms": float(np.sqrt(np.nanmean(angle_err**2))),
                "angle_log_max": float(np.nanmax(angle_err)),
                "pair_log_max": float(np.nanmax(pair_err)),
                "rho": float(rec.settings.get("prior_rho", float("nan"))),
                "out_of_plane": out_of_plane_share(cells),
                "mirror_gap": cells_gap_deg(cells),
                "peak_excess": rec.peak_excess_log_rmse,
                # The highlight-not-read statistic as finishing computes it (science.md 7.1.1).
                "highlight_excess": highlight_read(rec.table, cells, ph, alpha,
                                                   np.maximum(vals, 0.0)).excess,
                "reason": rec.misfit_warning,
                **(rec.misfit.as_dict() if rec.misfit is not None else {}),
            })
            if witnesses:
                from calibrate_log_rmse import witnesses as calibration_witnesses

                w = calibration_witnesses(b, cells, ph, alpha, vals, m.truth)
                rows[-1].update(z_loo_pair=w["z_loo_pair"], s2=w["s2"])
        print(f"  {m.name} ({time.perf_counter() - t0:.0f} s)", flush=True)
    return rows


def _plan_table(rows: list[dict[str, Any]], groups: tuple[tuple[str, Any], ...],
                cell: Callable[[list[dict[str, Any]]], str]) -> None:
    """Print a markdown table: one line per plan (and every plan), one column per group of
    scans, each cell ``cell(scans)`` (empty where the group has no scan of that plan)."""
    print("| plan | " + " | ".join(g for g, _ in groups) + " |")
    print("|---" * (1 + len(groups)) + "|")
    for label in [p[0] for p in PLANS] + ["every plan"]:
        sel = [r for r in rows if label == "every plan" or r["plan"] == label]
        cells = []
        for _, g in groups:
            s = [r for r in sel if g(r)]
            cells.append(cell(s) if s else "")
        print(f"| {label} | " + " | ".join(cells) + " |")


def table(rows: list[dict[str, Any]]) -> None:
    """The per-plan tables and the summary (module docstring)."""
    missing = sorted({k for r in rows for k in ("unwidened", "uncovered", "misfit_log")
                      if k not in r})
    if missing:
        raise SystemExit(f"--rows file lacks {', '.join(missing)} (written by an older bench): "
                         "rerun without --rows to measure the rows again")
    for r in rows:
        if row_misfit(r).flagged != bool(r["reason"]):
            raise SystemExit(f"--rows file: {r['material']} ({r['plan']}) was "
                             f"{'' if r['reason'] else 'not '}flagged, which today's misfit "
                             "rule does not reproduce: rerun without --rows")
        # "refit" is the rejected candidate, from the same scan's inputs.
        r["refit"] = refit_candidate(r)
        r.setdefault("set", "cal" if r["cal"] else "validation")
    for label, _, _ in PLANS:
        print(f"\n#### {label}\n")
        print("| material | set | true log_rmse | refit | ratio | shipped | ratio | within x2 | "
              "> 2x low | uncovered | misfit chi2 | misfit (log) | persistent pairs | "
              "basis_misfit |")
        print("|---" * 14 + "|")
        for r in (r for r in rows if r["plan"] == label):
            q0, q1 = r["refit"] / r["truth"], r["widened"] / r["truth"]
            print(f"| {r['material']} | {r['set']} | {r['truth']:.4f} | "
                  f"{r['refit']:.4f} | x{q0:.2f} | {r['widened']:.4f} | x{q1:.2f} | "
                  f"{'yes' if 0.5 <= q1 <= 2 else 'no'} | {'LOW' if q1 < 0.5 else ''} | "
                  f"{r.get('uncovered', float('nan')):.3f} | {r['misfit_chi2']:.3g} | "
                  f"{r['misfit_log']:.4f} | "
                  f"{r['misfit_persistent_pairs']} | {'yes' if r['reason'] else ''} |")
    print("\nwithin x2 (more than 2x low, lowest ratio), the rejected refit -> the shipped final "
          "mapping:\n")
    groups: tuple[tuple[str, Any], ...] = (
              ("calibration", lambda r: r["set"] == "cal"),
              ("choice", lambda r: r["set"] == "choice"),
              ("test", lambda r: r["set"] == "test"),
              ("test measured", lambda r: r["set"] == "test" and r["kind"] == "measured"),
              ("test asymmetric", lambda r: r["set"] == "test" and r["kind"] == "asymmetric"),
              ("test untilted", lambda r: r["set"] == "test" and r["kind"] == "untilted"),
              ("fresh", lambda r: r["set"] == "fresh"),
              ("fresh tilted", lambda r: r["kind"] == "fresh-tilted"),
              ("fresh-inplane", lambda r: r["set"] == "fresh-inplane"),
              ("fresh-confirm", lambda r: r["set"] == "fresh-confirm"),
              ("all", lambda r: True))

    def count(key: str, s: list[dict[str, Any]]) -> str:
        q = np.array([r[key] / r["truth"] for r in s])
        ok = int(np.sum((q >= 0.5) & (q <= 2.0)))
        return f"{ok}/{q.size} ({int(np.sum(q < 0.5))}, x{q.min():.2f})"

    _plan_table(rows, groups, lambda s: f"{count('refit', s)} -> {count('widened', s)}")
    if all(np.isfinite(r.get("upper", float("nan"))) for r in rows):
        print("\ntrue log_rmse above the interval's upper end (predicted_log_rmse_upper), of "
              "the scans; median upper / true:\n")

        def above(s: list[dict[str, Any]]) -> str:
            u = np.array([r["upper"] / r["truth"] for r in s])
            return f"{int(np.sum(u < 1.0))}/{u.size} (x{np.median(u):.2f})"

        _plan_table(rows, groups, above)
    upper_factor_table(rows)
    print("\nscans flagged basis_misfit (of the scans), per plan and set:\n")
    _plan_table(rows, groups, lambda s: f"{sum(bool(r['reason']) for r in s)}/{len(s)}")
    low = [r for r in rows if r["widened"] / r["truth"] < 0.5]
    print(f"\nmore than 2x too low after the final mapping: {len(low)} scans, "
          f"{sum(bool(r['reason']) for r in low)} of them flagged; their misfit chi2 "
          f"{min((r['misfit_chi2'] for r in low), default=float('nan')):.3g}-"
          f"{max((r['misfit_chi2'] for r in low), default=float('nan')):.3g}; plans "
          f"{sorted({r['plan'] for r in low})}")
    if low and "z_loo_pair" in low[0]:
        # A standardised leave-one-pair-out error near 1 (or below) says the posterior predicts
        # the error at the pairs as large as it is: what it misses lies where no pair looks.
        z = np.array([r["z_loo_pair"] for r in low])
        print(f"their standardised leave-one-pair-out error z_loo_pair: median {np.median(z):.2f}, "
              f"range {z.min():.2f}-{z.max():.2f} (1: as the posterior expects)")


def upper_factor_table(rows: list[dict[str, Any]]) -> None:
    """Where the interval's upper factors come from: the 98th percentile of true / estimate
    (the shipped final mapping's) per set, for the scans whose fit holds its readings and the
    flagged ones (:func:`~gonio.brdf.reconstruction.selfcheck.upper_factor_from`; numpy's
    default linear interpolation beside it), and how many scans lie above the shipped factor.
    The factors are the calibration set's; the other sets are for information."""
    print("\n98th percentile of true / estimate (the interval's upper factor; the calibration "
          "set's is shipped), scans above the shipped factor:\n")
    print("| set | not flagged: scans | p98 (higher) | p98 (linear) | above x"
          f"{UPPER_FACTOR:g} | flagged: scans | p98 (higher) | p98 (linear) | above x"
          f"{UPPER_FACTOR_FLAGGED:g} |")
    print("|---" * 9 + "|")
    cal: dict[bool, float] = {}
    for which in SETS:
        cells = []
        for flagged, shipped in ((False, UPPER_FACTOR), (True, UPPER_FACTOR_FLAGGED)):
            q = np.array([r["truth"] / r["widened"] for r in rows
                          if r["set"] == which and bool(r["reason"]) == flagged])
            if q.size == 0:
                cells.append("0 | | | ")
                continue
            p98, factor = upper_factor_from(q)
            if which == "cal":
                cal[flagged] = factor
            cells.append(f"{q.size} | {p98:.4f} | {np.percentile(q, UPPER_PERCENTILE):.4f} | "
                         f"{int(np.sum(q > shipped))}")
        print(f"| {which} | " + " | ".join(cells) + " |")
    for flagged, shipped, name in ((False, UPPER_FACTOR, "UPPER_FACTOR"),
                                   (True, UPPER_FACTOR_FLAGGED, "UPPER_FACTOR_FLAGGED")):
        if flagged in cal:
            print(f"calibration p98 rounded up to 0.01: {cal[flagged]:.2f}, shipped {name} "
                  f"{shipped:.2f}: " + ("reproduced" if cal[flagged] == shipped
                                        else f"DIFFERS by {cal[flagged] - shipped:+.2f}"))


def in_plane_term(in_plane_share: float, cv_log_error: float,
                  scale: float) -> float:
    """What a layout in the plane of incidence cannot show: ``scale s_in cv_log_error``.

    A pair whose light and sensor lie in one plane through the normal reads one slice of each
    ``(th, td)`` profile; when most pairs do (the instrument presets), every other plane of the
    table is the prior's guess, and the posterior's own variance (``expected``) takes that guess
    as the library's average. How badly the pairs predict each other when one is left out
    (``cv_log_error``, the leave-one-pair-out RMS log error of the readings) is then the one
    witness the readings give of how far the specimen is from that average.

    Parameters
    ----------
    in_plane_share : float
        Share of the pairs reading in the plane of incidence, 0..1 (1 minus
        :func:`gonio.brdf.reconstruction.localprior.out_of_plane_share`).
    cv_log_error : float
        Leave-one-pair-out RMS log error (dimensionless, natural log); NaN (no pair could be
        left out) gives 0.
    scale : float
        The term's coefficient (dimensionless).

    Returns
    -------
    float
        ``log_rmse`` units, >= 0.
    """
    s, c = float(in_plane_share), float(cv_log_error)
    if not (np.isfinite(s) and np.isfinite(c)) or scale == 0:
        return 0.0
    return float(scale * min(max(s, 0.0), 1.0) * max(c, 0.0))


#: The in-plane candidate's coefficients tried on the calibration set (:func:`in_plane_study`).
IN_PLANE_GRID: tuple[float, ...] = tuple(round(0.05 * i, 2) for i in range(31))


def in_plane_candidate(row: dict[str, Any], k: float) -> float:
    """The shipped final mapping of a row plus the in-plane term with coefficient ``k``
    (:func:`in_plane_term`; ``log_rmse`` units)."""
    term = in_plane_term(1.0 - row["out_of_plane"], row["cv_log_error"], k)
    # Under the same floor as the shipped estimate (reconstruct: the error above the peak
    # bound; rows written before it have none).
    return max(final_log_rmse(row["unwidened"], row["uncovered"], row_misfit(row),
                              in_plane=term), peak_floor(row))


def _counts(sel: list[dict[str, Any]], estimate: Callable[[dict[str, Any]], float]
            ) -> tuple[int, int, int]:
    """(within x2, more than 2x low, scans) of ``estimate`` over ``sel``."""
    q = np.array([estimate(r) / r["truth"] for r in sel])
    return int(np.sum((q >= 0.5) & (q <= 2.0))), int(np.sum(q < 0.5)), int(q.size)


def in_plane_study(rows: list[dict[str, Any]]) -> float | None:
    """The in-plane candidate (issue 23 item 4), its protocol written before any of its sets
    was scanned for it (2026-11-27; science.md 7.1.1): returns the chosen coefficient, or None
    when the rows lack what it needs.

    * **Form.** The shipped final mapping with ``in_plane_term(s_in, cv_log_error, k)`` added
      as a variance beside the coverage term, ``s_in`` the share of the pairs reading in the
      plane of incidence (1 for MA68, 11/19 for MA98, 0.1 for the default design).
    * **Fit (calibration set only).** ``k`` over :data:`IN_PLANE_GRID`: the fewest scans more
      than 2x low, then the most within x2, then the smallest ``k``.
    * **Choice set.** Adopted when it leaves no more choice scans more than 2x low than the
      shipped mapping and at most one fewer within x2.
    * **Test, fresh, fresh-inplane.** Printed once for both mappings. The test and fresh sets' MA98
      rows were looked at before the form was written down, so only :data:`FRESH_INPLANE` is blind;
      the candidate ships only if it also leaves no more fresh-inplane scans more than 2x low.
    """
    if any("out_of_plane" not in r for r in rows):
        print("\nin-plane candidate: the rows lack out_of_plane (written by an older bench); "
              "rerun without --rows")
        return None
    cal = [r for r in rows if r["set"] == "cal"]
    print("\n#### The in-plane candidate (science.md 7.1.1)\n")
    print("| k | calibration within x2 | more than 2x low |")
    print("|---|---|---|")
    best: tuple[int, int, float] | None = None
    for k in IN_PLANE_GRID:
        w, lo, n = _counts(cal, lambda r, k=k: in_plane_candidate(r, k))
        print(f"| {k:.2f} | {w}/{n} | {lo} |")
        key = (lo, -w, k)
        if best is None or key < best:
            best = key
    assert best is not None
    k = best[2]
    print(f"\nchosen on the calibration set: k = {k:.2f}\n")
    print("| set | plan | shipped: within x2 / more than 2x low | candidate |")
    print("|---|---|---|---|")
    verdict: dict[str, tuple[tuple[int, int, int], tuple[int, int, int]]] = {}
    for which in SETS:
        sel_set = [r for r in rows if r["set"] == which]
        if not sel_set:
            continue
        for label in [pl[0] for pl in PLANS] + ["every plan"]:
            sel = [r for r in sel_set if label == "every plan" or r["plan"] == label]
            a = _counts(sel, lambda r: r["widened"])
            b = _counts(sel, lambda r: in_plane_candidate(r, k))
            print(f"| {which} | {label} | {a[0]}/{a[2]} / {a[1]} | {b[0]}/{b[2]} / {b[1]} |")
            if label == "every plan":
                verdict[which] = (a, b)
    if "choice" in verdict:
        (aw, al, _), (bw, bl, _) = verdict["choice"]
        adopted = bl <= al and bw >= aw - 1
        print(f"\nchoice rule: {'adopted' if adopted else 'not adopted'} (choice: shipped "
              f"{aw} within x2 / {al} low, candidate {bw} / {bl})")
        if adopted and "fresh-inplane" in verdict:
            (_, fl, _), (_, gl, _) = verdict["fresh-inplane"]
            print(f"fresh-inplane guard: {'passed' if gl <= fl else 'FAILED'} (more than 2x low: "
                  f"shipped {fl}, candidate {gl})")
    return k


#: The in-plane candidate's coefficient as chosen on the calibration set by
#: :func:`in_plane_study` on 2026-11-27 (science.md 7.1.1): fixed for its confirmation.
CONFIRM_K = 0.90
#: How many more of the blind set's scans the candidate may leave outside x2 (5 % of 80).
CONFIRM_WITHIN_SLACK = 4


def confirm_in_plane(rows: list[dict[str, Any]]) -> bool | None:
    """The in-plane candidate's confirmation on a blind set (issue 23 item 4), its rule written
    down and committed on 2026-11-27 before any scan of :data:`FRESH_CONFIRM`.

    Why a second test: the candidate (:func:`in_plane_study`) failed its choice rule (three
    fewer choice scans within x2, no low scan saved), while on the three sets printed after
    that decision it took the scans more than 2x low from 7 to 2 at a cost of 10 within x2.
    Those sets had made no decision, but they were looked at, so they cannot confirm it. The
    issue ranks the dangerous direction first ("never more than 2x low"), which this rule
    weighs explicitly. Hypothesis formed on seen sets; tested once here.

    * **Candidate**: the shipped final mapping plus ``in_plane_term`` with ``k`` =
      :data:`CONFIRM_K`, not refitted.
    * **Blind set**: the 80 scans of ``fresh-confirm`` (16 specimens x 5 plans), scanned once.
    * **Adopt** when, over those 80 scans, the candidate leaves strictly fewer scans more than
      2x low than the shipped mapping and at most :data:`CONFIRM_WITHIN_SLACK` fewer within
      x2. When the shipped mapping leaves none low there, there is nothing to confirm: not
      adopted.

    Returns None when the rows hold no ``fresh-confirm`` scan.
    """
    sel = [r for r in rows if r["set"] == "fresh-confirm"]
    if not sel or any("out_of_plane" not in r for r in sel):
        return None
    print("\n#### The in-plane candidate's confirmation on fresh-confirm (science.md 7.1.1)\n")
    print(f"k = {CONFIRM_K:.2f} (fixed); within x2 / more than 2x low / scans\n")
    print("| plan | shipped | candidate |")
    print("|---|---|---|")
    for label in [pl[0] for pl in PLANS] + ["every plan"]:
        part = [r for r in sel if label == "every plan" or r["plan"] == label]
        a = _counts(part, lambda r: r["widened"])
        b = _counts(part, lambda r: in_plane_candidate(r, CONFIRM_K))
        print(f"| {label} | {a[0]} / {a[1]} / {a[2]} | {b[0]} / {b[1]} / {b[2]} |")
    (aw, al, _), (bw, bl, _) = (_counts(sel, lambda r: r["widened"]),
                                _counts(sel, lambda r: in_plane_candidate(r, CONFIRM_K)))
    adopted = bl < al and bw >= aw - CONFIRM_WITHIN_SLACK
    print(f"\nconfirmation rule: {'ADOPT' if adopted else 'not adopted'} (shipped {aw} within "
          f"x2 / {al} low, candidate {bw} / {bl})")
    return adopted


def excess_of(row: dict[str, Any]) -> float:
    """A row's ``highlight_excess``; 1 (nothing beyond the readings) when it is NaN, missing or
    not positive."""
    e = float(row.get("highlight_excess", float("nan")))
    return e if np.isfinite(e) and e > 0 else 1.0


def highlight_flagged(row: dict[str, Any]) -> bool:
    """True when the scan's result would carry ``highlight_not_read`` (excess above
    :data:`~gonio.brdf.highlightread.EXCESS_LIMIT`)."""
    return excess_of(row) > EXCESS_LIMIT


def _verdict(q: float) -> str:
    return "low" if q < 0.5 else ("high" if q > 2.0 else "within")


def before_highlight(row: dict[str, Any]) -> float:
    """A row's estimate by the final mapping without the highlight term (the shipped estimate
    when the study was decided; :func:`highlight_candidate` at parameter 0)."""
    return highlight_candidate(row, "variance", 0.0)


def highlight_cross_table(rows: list[dict[str, Any]]) -> None:
    """Per set (calibration first): the scans more than 2x low under the estimate without the
    highlight term (:func:`before_highlight`) with their ``highlight_excess``, and flagged /
    not flagged x low / within x2 / high; then how many stay low under the shipped estimate
    (with the term since 2026-11-28)."""
    if any("highlight_excess" not in r for r in rows):
        print("\nhighlight cross-table: the rows lack highlight_excess (written by an older "
              "bench); rerun without --rows")
        return
    print(f"\n#### Highlight not read (excess > {EXCESS_LIMIT:g}) against the estimate "
          "without the highlight term (science.md 7.1.1)\n")
    for which in SETS:
        sel = [r for r in rows if r["set"] == which]
        if not sel:
            continue
        low = [r for r in sel if before_highlight(r) / r["truth"] < 0.5]
        print(f"\n{which}: {len(sel)} scans, {len(low)} more than 2x low; with the shipped "
              f"estimate {sum(r['widened'] / r['truth'] < 0.5 for r in sel)}")
        for r in low:
            print(f"  {r['material']} ({r['plan']}): x{before_highlight(r) / r['truth']:.2f} "
                  f"(shipped x{r['widened'] / r['truth']:.2f}), excess {excess_of(r):.3g}"
                  f"{' FLAGGED' if highlight_flagged(r) else ''}")
        print("\n| | low | within x2 | high |")
        print("|---|---|---|---|")
        for flagged in (True, False):
            v = [_verdict(before_highlight(r) / r["truth"]) for r in sel
                 if highlight_flagged(r) == flagged]
            print(f"| {'flagged' if flagged else 'not flagged'} | {v.count('low')} | "
                  f"{v.count('within')} | {v.count('high')} |")


#: The highlight widening's grids (:func:`highlight_study`): ``g`` of ``"widen"``, ``s`` of
#: ``"variance"``.
HIGHLIGHT_GRIDS: dict[str, tuple[float, ...]] = {
    "widen": tuple(round(0.05 * i, 2) for i in range(41)),
    "variance": tuple(round(0.0025 * i, 4) for i in range(61)),
}


def highlight_candidate(row: dict[str, Any], form: str, p: float) -> float:
    """The estimate of a row widened by its ``highlight_excess`` (module docstring): ``form``
    ``"widen"`` (``est max(1, e / 3.4)^p``) or ``"variance"`` (``p ln(max(e, 1))`` beside the
    coverage term); under the shipped peak floor. ``p`` = 0 gives the shipped estimate."""
    e = excess_of(row)
    misfit = row_misfit(row)
    if form == "widen":
        # The mapping before the highlight term (rows written after its wiring carry it in
        # "widened"; this candidate replaces it).
        est = final_log_rmse(row["unwidened"], row["uncovered"], misfit, highlight_excess=1.0)
        est *= max(1.0, e / EXCESS_LIMIT) ** p
    elif form == "variance":
        est = final_log_rmse(row["unwidened"], row["uncovered"], misfit, highlight_excess=1.0,
                             in_plane=p * np.log(max(e, 1.0)))
    else:
        raise ValueError(f"unknown form {form!r}")
    return max(est, peak_floor(row))


def highlight_study(rows: list[dict[str, Any]]) -> bool | None:
    """The highlight widening, its rule committed before any of its rows (module docstring):
    returns whether it is adopted, None when the rows lack ``highlight_excess``.

    Prints, in this order: the calibration fit over both forms, the choice set's verdict, the
    test and fresh sets (once), then :data:`FRESH_WIDE`'s blind set."""
    if any("highlight_excess" not in r for r in rows):
        return None
    by = {w: [r for r in rows if r["set"] == w] for w in SETS}
    def reproduced(p: float) -> int:
        return sum(abs(highlight_candidate(r, "variance", p) - r["widened"])
                   <= 1e-9 * max(r["widened"], 1.0) for r in rows)

    print(f"\n#### The highlight widening (science.md 7.1.1)\n\nrows whose shipped estimate "
          f"the candidate reproduces at parameter 0 (rows written before the term's wiring): "
          f"{reproduced(0.0)} of {len(rows)}; at the shipped FINAL_HIGHLIGHT_SCALE "
          f"{FINAL_HIGHLIGHT_SCALE:g} (rows written after): {reproduced(FINAL_HIGHLIGHT_SCALE)}")
    print("\ncalibration fit: within x2 / more than 2x low / scans\n")
    print("| form | parameter | calibration |")
    print("|---|---|---|")
    best: tuple[int, int, int, float] | None = None
    for fi, (form, grid) in enumerate(HIGHLIGHT_GRIDS.items()):
        for p in grid:
            w, lo, n = _counts(by["cal"], lambda r, f=form, p=p: highlight_candidate(r, f, p))
            print(f"| {form} | {p:g} | {w} / {lo} / {n} |")
            key = (lo, -w, fi, p)
            if best is None or key < best:
                best = key
    assert best is not None
    form, p = list(HIGHLIGHT_GRIDS)[best[2]], best[3]
    print(f"\nchosen on the calibration set: {form}, parameter {p:g}")

    def compare(names: tuple[str, ...]) -> tuple[tuple[int, int, int], tuple[int, int, int]]:
        print("\n| set | plan | without the term: within x2 / low / scans | candidate |")
        print("|---|---|---|---|")
        out = ((0, 0, 0), (0, 0, 0))
        for which in names:
            for label in [pl[0] for pl in PLANS] + ["every plan"]:
                sel = [r for r in by[which] if label == "every plan" or r["plan"] == label]
                if not sel:
                    continue
                a = _counts(sel, before_highlight)
                b = _counts(sel, lambda r: highlight_candidate(r, form, p))
                print(f"| {which} | {label} | {a[0]} / {a[1]} / {a[2]} | "
                      f"{b[0]} / {b[1]} / {b[2]} |")
                if label == "every plan":
                    out = (tuple(x + y for x, y in zip(out[0], a, strict=True)),  # type: ignore[assignment]
                           tuple(x + y for x, y in zip(out[1], b, strict=True)))
        return out

    print("\ncalibration:")
    compare(("cal",))
    if p == 0:
        print("\nthe calibration set prefers the shipped estimate: not adopted")
        return False
    print("\nchoice:")
    (aw, al, _), (bw, bl, _) = compare(("choice",))
    adopted = bl <= al and bw >= aw - 1
    print(f"\nchoice rule: {'passed' if adopted else 'FAILED'} (without the term {aw} within "
          f"x2 / {al} low, candidate {bw} / {bl})")
    print("\ntest and fresh (printed once):")
    (aw, al, _), (bw, bl, _) = compare(("test", "fresh", "fresh-inplane", "fresh-confirm"))
    ok = bl <= al
    adopted = adopted and ok
    print(f"\ntest and fresh rule: {'passed' if ok else 'FAILED'} (without the term {aw} "
          f"within x2 / {al} low, candidate {bw} / {bl})")
    print("\nfresh-wide (blind, last):")
    (aw, al, n), (bw, bl, _) = compare(("fresh-wide",))
    if n:
        ok = bl <= al
        adopted = adopted and ok
        print(f"\nfresh-wide rule: {'passed' if ok else 'FAILED'} (without the term {aw} "
              f"within x2 / {al} low, candidate {bw} / {bl})")
    print(f"\nhighlight widening: {'ADOPT' if adopted else 'not adopted'}")
    return adopted


#: The under-prediction term's grid (:func:`under_study`): ``v``, ``log_rmse`` units per log
#: unit of ``cv_log_under``.
UNDER_GRID: tuple[float, ...] = tuple(round(0.0025 * i, 4) for i in range(41))


def under_candidate(row: dict[str, Any], v: float, witness: str = "cv_log_under") -> float:
    """The shipped estimate of a row (highlight term included) with ``v w`` added as a
    variance beside the coverage term, ``w`` the row's ``witness`` (module docstring), under
    the peak floor; ``v`` = 0 gives the shipped estimate."""
    w = float(row.get(witness, float("nan")))
    term = v * w if np.isfinite(w) else 0.0
    return max(final_log_rmse(row["unwidened"], row["uncovered"], row_misfit(row),
                              in_plane=term, highlight_excess=excess_of(row)),
               peak_floor(row))


def under_study(rows: list[dict[str, Any]]) -> bool | None:
    """The leave-one-pair-out under-prediction term, its rule committed before any of its rows
    (module docstring): returns whether it is adopted, None when the rows lack
    ``cv_log_under``.

    Prints, in this order: the calibration set over the grid, the admissible values, the
    choice set over them and the value chosen, the test and fresh sets (once), fresh-wide,
    then :data:`FRESH_COAT`'s blind set."""
    if any("cv_log_under" not in r for r in rows):
        return None
    by = {w: [r for r in rows if r["set"] == w] for w in SETS}
    shipped = {w: _counts(by[w], lambda r: under_candidate(r, 0.0)) for w in SETS if by[w]}

    def reproduced(v: float) -> int:
        return sum(abs(under_candidate(r, v) - r["widened"]) <= 1e-9 * max(r["widened"], 1.0)
                   for r in rows)

    print(f"\n#### The leave-one-pair-out under-prediction term (science.md 7.1.1)\n\nrows "
          f"whose shipped estimate the candidate reproduces at v = 0 (rows written before the "
          f"term's wiring): {reproduced(0.0)} of {len(rows)}; at the shipped "
          f"FINAL_UNDER_SCALE {FINAL_UNDER_SCALE:g} (rows written after): "
          f"{reproduced(FINAL_UNDER_SCALE)}")
    print("\n| v | calibration: within x2 / low / scans | choice |")
    print("|---|---|---|")
    admissible, chosen = [], 0.0
    for v in UNDER_GRID:
        c = _counts(by["cal"], lambda r, v=v: under_candidate(r, v))
        h = _counts(by["choice"], lambda r, v=v: under_candidate(r, v))
        print(f"| {v:g} | {c[0]} / {c[1]} / {c[2]} | {h[0]} / {h[1]} / {h[2]} |")
        if c[1] <= shipped["cal"][1] and c[0] >= shipped["cal"][0]:
            admissible.append(v)
            if h[1] <= shipped["choice"][1] and h[0] >= shipped["choice"][0]:
                chosen = max(chosen, v)
    print(f"\nadmissible on the calibration set: {admissible}")
    print(f"chosen on the choice set: v = {chosen:g}")
    if chosen == 0:
        print("\nunder-prediction term: not adopted (nothing above 0 passes)")
        return False

    def compare(names: tuple[str, ...]) -> tuple[tuple[int, int, int], tuple[int, int, int]]:
        print("\n| set | plan | without the term: within x2 / low / scans | candidate | "
              "unsigned cv_log_error at the same v |")
        print("|---|---|---|---|---|")
        tot = [[0, 0, 0], [0, 0, 0]]
        for which in names:
            for label in [pl[0] for pl in PLANS] + ["every plan"]:
                sel = [r for r in by[which] if label == "every plan" or r["plan"] == label]
                if not sel:
                    continue
                a = _counts(sel, lambda r: under_candidate(r, 0.0))
                b = _counts(sel, lambda r: under_candidate(r, chosen))
                u = _counts(sel, lambda r: under_candidate(r, chosen, "cv_log_error"))
                print(f"| {which} | {label} | {a[0]} / {a[1]} / {a[2]} | {b[0]} / {b[1]} / "
                      f"{b[2]} | {u[0]} / {u[1]} / {u[2]} |")
                if label == "every plan":
                    for k in range(3):
                        tot[0][k] += a[k]
                        tot[1][k] += b[k]
        return (tot[0][0], tot[0][1], tot[0][2]), (tot[1][0], tot[1][1], tot[1][2])

    print("\ncalibration and choice:")
    compare(("cal", "choice"))
    print("\ntest and fresh (printed once):")
    (aw, al, _), (bw, bl, _) = compare(("test", "fresh", "fresh-inplane", "fresh-confirm"))
    adopted = bl <= al
    print(f"\ntest and fresh rule: {'passed' if adopted else 'FAILED'} (without {aw} within "
          f"x2 / {al} low, candidate {bw} / {bl})")
    print("\nfresh-wide (not blind):")
    (aw, al, n), (bw, bl, _) = compare(("fresh-wide",))
    ok = bool(n) and bl < al
    adopted = adopted and ok
    print(f"\nfresh-wide rule: {'passed' if ok else 'FAILED'} (without {aw} within x2 / {al} "
          f"low, candidate {bw} / {bl})")
    print("\nfresh-coat (blind, last):")
    (aw, al, n), (bw, bl, _) = compare(("fresh-coat",))
    ok = bool(n) and bl <= al
    adopted = adopted and ok
    print(f"\nfresh-coat rule: {'passed' if ok else 'FAILED'} (without {aw} within x2 / {al} "
          f"low, candidate {bw} / {bl})")
    print(f"\nunder-prediction term: {'ADOPT' if adopted else 'not adopted'}")
    return adopted


def _category(row: dict[str, Any]) -> str:
    """The kind of material of a calibration row for :func:`overprediction_cross_table`."""
    if row["kind"] == "library-asym":
        return "library asymmetric, " + ("flagged" if row["reason"] else "not flagged")
    return str(row["kind"])


def _largest_part(row: dict[str, Any]) -> str:
    """Which part of the shipped estimate of a row is the largest: the peak floor or the
    misfit floor when one sets the estimate, else the largest of the model's part (its factor
    times ``predicted``), the coverage, highlight and under terms."""
    misfit = row_misfit(row)
    pre = final_log_rmse(row["unwidened"], row["uncovered"], misfit,
                         highlight_excess=excess_of(row), cv_log_under=row["cv_log_under"])
    if peak_floor(row) >= pre:
        return "peak floor"
    k = FINAL_FLAGGED_FACTOR if misfit.flagged else FINAL_PREDICTED_FACTOR
    parts = {"model": k * row["unwidened"],
             "coverage": FINAL_COVERAGE_SCALE * np.sqrt(max(row["uncovered"], 0.0)),
             "highlight": highlight_term(excess_of(row)), "under": under_term(row["cv_log_under"])}
    if misfit.flagged and misfit.log_misfit >= float(np.sqrt(sum(v * v for v in parts.values()))):
        return "misfit floor"
    return max(parts, key=lambda p: parts[p])


def overprediction_cross_table(rows: list[dict[str, Any]]) -> None:
    """On the calibration set only: plan x kind of material (within x2 / more than 2x low /
    more than 2x high of the shipped estimate), and for the scans more than 2x high, which part
    of the mapping is the largest (:func:`_largest_part`) per plan."""
    if any("cv_log_under" not in r for r in rows):
        return
    cal = [r for r in rows if r["set"] == "cal"]
    plans = [p[0] for p in PLANS]
    print("\n#### Over-predictions on the calibration set (science.md 7.1.1)\n")
    print("within x2 / more than 2x low / more than 2x high (scans) of the shipped estimate\n")
    print("| kind | " + " | ".join(plans) + " | every plan |")
    print("|---" * (len(plans) + 2) + "|")
    for c in [*sorted({_category(r) for r in cal}), "every kind"]:
        cells = []
        for label in [*plans, "every plan"]:
            sel = [r for r in cal if c in ("every kind", _category(r))
                   and label in ("every plan", r["plan"])]
            v = [_verdict(r["widened"] / r["truth"]) for r in sel]
            cells.append(f"{v.count('within')} / {v.count('low')} / {v.count('high')} "
                         f"({len(v)})" if v else "")
        print(f"| {c} | " + " | ".join(cells) + " |")
    high = [r for r in cal if r["widened"] / r["truth"] > 2.0]
    print("\nthe scans more than 2x high, by the largest part of their estimate\n")
    print("| largest part | " + " | ".join(plans) + " | every plan |")
    print("|---" * (len(plans) + 2) + "|")
    for part in sorted({_largest_part(r) for r in high}):
        n = [sum(1 for r in high
                 if _largest_part(r) == part and label in ("every plan", r["plan"]))
             for label in [*plans, "every plan"]]
        print(f"| {part} | " + " | ".join(str(x) for x in n) + " |")
    for c in sorted({_category(r) for r in high}):
        sel = [r for r in high if _category(r) == c]
        print(f"\n{c}: {len(sel)} more than 2x high; median cv_sample_error "
              f"{np.median([r['cv_sample_error'] for r in sel]):.3g}, median cv_log_error "
              f"{np.median([r['cv_log_error'] for r in sel]):.3g}")


#: The over-prediction study's grids (:func:`high_study`): ``p`` of ``"outside-cap"`` (the cap
#: on the model's outside part in units of ``cv_log_error``; inf, the shipped mapping, is not in
#: it) and of ``"inplane-coverage"`` (the shrink of the coverage term of an in-plane layout).
HIGH_GRIDS: dict[str, tuple[float, ...]] = {
    "outside-cap": tuple(round(0.25 * i, 2) for i in range(1, 21)),
    "inplane-coverage": tuple(round(0.05 * i, 2) for i in range(15)),
}


def high_candidate(row: dict[str, Any], form: str, p: float) -> float:
    """The estimate of a row under the over-prediction study's candidate ``form`` with
    parameter ``p`` (module docstring): the shipped mapping (highlight and under terms, the
    misfit and peak floors) with the model's outside part of an unflagged scan capped at
    ``p cv_log_error`` (``"outside-cap"``), or the coverage term of a layout with no pair out
    of the plane of incidence times ``1 - p`` (``"inplane-coverage"``; ``p`` = 0 is the shipped
    estimate)."""
    misfit = row_misfit(row)
    undetermined, outside = estimate_parts(row["expected"], row["mahalanobis"],
                                           row["cv_sample_error"])
    uncovered = row["uncovered"]
    if form == "outside-cap":
        cv = float(row["cv_log_error"])
        if not misfit.flagged and np.isfinite(cv):
            outside = min(outside, p * cv)
    elif form == "inplane-coverage":
        if row["out_of_plane"] <= 0.0:
            uncovered = uncovered * (1.0 - p) ** 2
    else:
        raise ValueError(f"unknown form {form!r}")
    return max(final_log_rmse(float(np.hypot(undetermined, outside)), uncovered, misfit,
                              highlight_excess=excess_of(row), cv_log_under=row["cv_log_under"]),
               peak_floor(row))


def _three(sel: list[dict[str, Any]], estimate: Callable[[dict[str, Any]], float]
           ) -> tuple[int, int, int, int, int]:
    """(within x2, more than 2x low, more than 2x high, truth above the upper end, scans) of
    ``estimate`` over ``sel`` (upper end: the shipped factor of the scan's kind times it)."""
    q = np.array([estimate(r) / r["truth"] for r in sel])
    f = np.array([UPPER_FACTOR_FLAGGED if r["reason"] else UPPER_FACTOR for r in sel])
    return (int(np.sum((q >= 0.5) & (q <= 2.0))), int(np.sum(q < 0.5)), int(np.sum(q > 2.0)),
            int(np.sum(f * q < 1.0)), int(q.size))


def high_study(rows: list[dict[str, Any]]) -> bool | None:
    """The over-prediction study, its rule committed before any candidate was computed outside
    the calibration set (module docstring): returns whether it is adopted, None when the rows
    lack what it needs.

    Prints, in this order: the calibration fit over both forms, the choice set's verdict, the
    test and fresh sets (once), fresh-wide and fresh-coat, the interval's factor, then
    :data:`FRESH_HIGH`'s blind set."""
    if any("cv_log_under" not in r for r in rows):
        return None
    by = {w: [r for r in rows if r["set"] == w] for w in SETS}
    shipped_ok = sum(abs(high_candidate(r, "inplane-coverage", 0.0) - r["widened"])
                     <= 1e-9 * max(r["widened"], 1.0) for r in rows)
    print(f"\n#### The over-prediction study (science.md 7.1.1)\n\nrows whose shipped estimate "
          f"the candidate reproduces at inplane-coverage 0: {shipped_ok} of {len(rows)}")
    base = _counts(by["cal"], lambda r: r["widened"])
    print(f"\ncalibration fit (shipped: {base[0]} within x2 / {base[1]} low / {base[2]} scans)\n")
    print("| form | parameter | calibration: within x2 / low / scans |")
    print("|---|---|---|")
    best: tuple[int, int, int, float] | None = None
    for fi, (form, grid) in enumerate(HIGH_GRIDS.items()):
        for p in grid:
            w, lo, n = _counts(by["cal"], lambda r, f=form, p=p: high_candidate(r, f, p))
            print(f"| {form} | {p:g} | {w} / {lo} / {n} |")
            # nearer the shipped mapping: the larger cap, the smaller shrink
            key = (lo, -w, fi, -p if form == "outside-cap" else p)
            if best is None or key < best:
                best = key
    assert best is not None
    form = list(HIGH_GRIDS)[best[2]]
    p = -best[3] if form == "outside-cap" else best[3]
    print(f"\nchosen on the calibration set: {form}, parameter {p:g}")
    if best[0] > base[1] or -best[1] <= base[0]:
        print("\nno gain within x2 at no more low on the calibration set: not adopted")
        return False

    def cand(r: dict[str, Any]) -> float:
        return high_candidate(r, form, p)

    def compare(names: tuple[str, ...]) -> tuple[tuple[int, ...], tuple[int, ...]]:
        return _compare_sets(by, names, cand)

    print("\ncalibration:")
    compare(("cal",))
    print("\nchoice:")
    a, b = compare(("choice",))
    adopted = b[1] <= a[1] and b[0] > a[0]
    print(f"\nchoice rule: {'passed' if adopted else 'FAILED'} (shipped {a[0]} within x2 / "
          f"{a[1]} low, candidate {b[0]} / {b[1]})")
    print("\ntest and fresh (printed once):")
    a, b = compare(("test", "fresh", "fresh-inplane", "fresh-confirm"))
    ok = b[1] <= a[1]
    adopted = adopted and ok
    print(f"\ntest and fresh rule: {'passed' if ok else 'FAILED'} (shipped {a[0]} within x2 / "
          f"{a[1]} low, candidate {b[0]} / {b[1]})")
    print("\nfresh-wide and fresh-coat:")
    a, b = compare(("fresh-wide", "fresh-coat"))
    ok = b[1] <= a[1]
    adopted = adopted and ok
    print(f"\nfresh-wide and fresh-coat rule: {'passed' if ok else 'FAILED'} (shipped {a[0]} "
          f"within x2 / {a[1]} low, candidate {b[0]} / {b[1]})")
    q = [r["truth"] / cand(r) for r in by["cal"] if not r["reason"]]
    p98, factor = upper_factor_from(q)
    print(f"\nthe interval: the candidate's calibration p98 of true / estimate (not flagged) "
          f"{p98:.4f} -> {factor:g} against UPPER_FACTOR {UPPER_FACTOR:g}: "
          f"{'keep UPPER_FACTOR' if factor <= UPPER_FACTOR else f'take {factor:g}'}")
    print("\nfresh-high (blind, last):")
    a, b = compare(("fresh-high",))
    ok = b[4] > 0 and b[1] <= a[1]
    adopted = adopted and ok
    print(f"\nfresh-high rule: {'passed' if ok else 'FAILED'} (shipped {a[0]} within x2 / "
          f"{a[1]} low, candidate {b[0]} / {b[1]})")
    # Its rule passed, but the cap was not wired: its gain was on the calibration set alone
    # and two held-out scans moved toward the low edge (docs/science.md 7.1.1.1).
    print(f"\nover-prediction study: {'rule passed' if adopted else 'rule failed'}; "
          "not wired into gonio (docs/science.md 7.1.1.1 says why)")
    return adopted


#: The coverage shrink's grid (:func:`cov_study`): ``c`` of both forms (``log_rmse`` units; the
#: shipped mapping is ``c`` -> 0, not in it).
COV_GRID: tuple[float, ...] = tuple(round(0.01 * i, 2) for i in range(1, 51))
#: The forms of :func:`cov_candidate`, in the order the rule prefers them on a tie.
COV_FORMS: tuple[str, ...] = ("cov-linear", "cov-sqrt")
#: The plans whose layout is designed (the joint fit's expected error), not a preset.
DESIGNED_PLANS: frozenset[str] = frozenset(label for label, d, _ in PLANS if d == "posterior")


def cov_candidate(row: dict[str, Any], form: str, c: float) -> float:
    """The estimate of a row under the coverage shrink ``form`` with parameter ``c``
    (module docstring): the shipped mapping (highlight and under terms, the misfit and peak
    floors) with, for a designed layout, the coverage term times ``min(1, cv_log_error / c)``
    (``"cov-linear"``) or ``min(1, sqrt(cv_log_error / c))`` (``"cov-sqrt"``)."""
    if form not in COV_FORMS:
        raise ValueError(f"unknown form {form!r}; one of {', '.join(COV_FORMS)}")
    uncovered = float(row["uncovered"])
    cv = float(row["cv_log_error"])
    if row["plan"] in DESIGNED_PLANS and np.isfinite(cv) and c > 0:
        ratio = max(cv, 0.0) / c
        shrink = min(1.0, ratio if form == "cov-linear" else float(np.sqrt(ratio)))
        uncovered = uncovered * shrink**2  # the term is FINAL_COVERAGE_SCALE sqrt(uncovered)
    return max(final_log_rmse(row["unwidened"], uncovered, row_misfit(row),
                              highlight_excess=excess_of(row), cv_log_under=row["cv_log_under"]),
               peak_floor(row))


def _compare_sets(by: dict[str, list[dict[str, Any]]], names: tuple[str, ...],
                 cand: Callable[[dict[str, Any]], float]
                 ) -> tuple[tuple[int, ...], tuple[int, ...]]:
    """Print shipped against candidate per set and plan (:func:`_three`); return the totals
    over ``names`` (every plan) of both."""
    print("\n| set | plan | shipped: within x2 / low / high / above upper / scans | "
          "candidate |")
    print("|---|---|---|---|")
    tot = [[0] * 5, [0] * 5]
    for which in names:
        for label in [pl[0] for pl in PLANS] + ["every plan"]:
            sel = [r for r in by.get(which, []) if label in ("every plan", r["plan"])]
            if not sel:
                continue
            a, b = _three(sel, lambda r: r["widened"]), _three(sel, cand)
            print(f"| {which} | {label} | {' / '.join(map(str, a))} | "
                  f"{' / '.join(map(str, b))} |")
            if label == "every plan":
                for k in range(5):
                    tot[0][k] += a[k]
                    tot[1][k] += b[k]
    return tuple(tot[0]), tuple(tot[1])


def _interval_line(by: dict[str, list[dict[str, Any]]],
                   cand: Callable[[dict[str, Any]], float]) -> None:
    """Print the candidate's calibration p98 of true / estimate (scans not flagged) and
    whether the interval keeps ``UPPER_FACTOR`` (the studies' interval step)."""
    q = [r["truth"] / cand(r) for r in by["cal"] if not r["reason"]]
    p98, factor = upper_factor_from(q)
    print(f"\nthe interval: the candidate's calibration p98 of true / estimate (not flagged) "
          f"{p98:.4f} -> {factor:g} against UPPER_FACTOR {UPPER_FACTOR:g}: "
          f"{'keep UPPER_FACTOR' if factor <= UPPER_FACTOR else f'take {factor:g}'}")


def _blind_rule(rows: list[dict[str, Any]], by: dict[str, list[dict[str, Any]]], which: str,
                cand: Callable[[dict[str, Any]], float],
                scan_blind: Callable[[], list[dict[str, Any]]] | None) -> bool:
    """A study's last step: scan the blind set ``which`` if the rows have none of it (after the
    choice; appended to ``rows``), print it, and return whether the candidate leaves no more
    of its scans more than 2x low than the shipped estimate."""
    if not by[which] and scan_blind is not None:
        print(f"\nscanning {which} (blind) after the choice:", flush=True)
        blind = scan_blind()
        rows.extend(blind)
        by[which] = blind
    print(f"\n{which} (blind, last):")
    a, b = _compare_sets(by, (which,), cand)
    ok = b[4] > 0 and b[1] <= a[1]
    print(f"\n{which} rule: {'passed' if ok else 'FAILED'} (shipped {a[0]} within x2 / "
          f"{a[1]} low, candidate {b[0]} / {b[1]})")
    return ok


def cov_study(rows: list[dict[str, Any]],
              scan_blind: Callable[[], list[dict[str, Any]]] | None = None) -> bool | None:
    """The coverage shrink, its rule committed before any candidate was computed outside the
    calibration set and before any scan of :data:`FRESH_COV` (module docstring): returns
    whether it is adopted, None when the rows lack what it needs.

    Prints, in this order: the calibration fit over both forms, the choice set's verdict, the
    test and fresh sets (once), fresh-wide, fresh-coat and fresh-high, the interval's factor,
    then fresh-cov's blind set, which ``scan_blind`` scans (and which is appended to ``rows``)
    when ``rows`` has none of it."""
    if any("cv_log_under" not in r for r in rows):
        return None
    by = {w: [r for r in rows if r["set"] == w] for w in SETS}
    print("\n#### The coverage shrink (science.md 7.1.1)\n")
    base = _counts(by["cal"], lambda r: r["widened"])
    print(f"calibration fit (shipped: {base[0]} within x2 / {base[1]} low / {base[2]} scans)\n")
    print("| form | c | calibration: within x2 / low / scans |")
    print("|---|---|---|")
    best: tuple[int, int, int, float] | None = None
    for fi, form in enumerate(COV_FORMS):
        for c in COV_GRID:
            w, lo, n = _counts(by["cal"], lambda r, f=form, c=c: cov_candidate(r, f, c))
            print(f"| {form} | {c:g} | {w} / {lo} / {n} |")
            key = (lo, -w, fi, c)  # nearer the shipped mapping: the smaller c
            if best is None or key < best:
                best = key
    assert best is not None
    form, c = COV_FORMS[best[2]], best[3]
    print(f"\nchosen on the calibration set: {form}, c = {c:g}")
    adopted = best[0] <= base[1] and -best[1] > base[0]
    if not adopted:
        print("\nno gain within x2 at no more low on the calibration set: not adopted")

    def cand(r: dict[str, Any]) -> float:
        return cov_candidate(r, form, c)

    print("\ncalibration:")
    _compare_sets(by, ("cal",), cand)
    print("\nchoice:")
    a, b = _compare_sets(by, ("choice",), cand)
    ok = b[1] <= a[1] and b[0] > a[0]
    adopted = adopted and ok
    print(f"\nchoice rule: {'passed' if ok else 'FAILED'} (shipped {a[0]} within x2 / "
          f"{a[1]} low, candidate {b[0]} / {b[1]})")
    print("\ntest and fresh (printed once):")
    a, b = _compare_sets(by, ("test", "fresh", "fresh-inplane", "fresh-confirm"), cand)
    ok = b[1] <= a[1]
    adopted = adopted and ok
    print(f"\ntest and fresh rule: {'passed' if ok else 'FAILED'} (shipped {a[0]} within x2 / "
          f"{a[1]} low, candidate {b[0]} / {b[1]})")
    print("\nfresh-wide, fresh-coat and fresh-high:")
    a, b = _compare_sets(by, ("fresh-wide", "fresh-coat", "fresh-high"), cand)
    ok = b[1] <= a[1]
    adopted = adopted and ok
    print(f"\nfresh-wide, fresh-coat and fresh-high rule: {'passed' if ok else 'FAILED'} "
          f"(shipped {a[0]} within x2 / {a[1]} low, candidate {b[0]} / {b[1]})")
    _interval_line(by, cand)
    adopted = _blind_rule(rows, by, "fresh-cov", cand, scan_blind) and adopted
    print(f"\ncoverage shrink: {'ADOPT' if adopted else 'not adopted'} ({form}, c = {c:g})")
    return adopted


#: The mirror gap's grid (:func:`mirror_study`): ``m`` of both forms (``log_rmse`` units; the
#: shipped mapping is ``m`` = 0, not in it).
MIRROR_GRID: tuple[float, ...] = tuple(round(0.005 * i, 3) for i in range(1, 61))
#: The forms of :func:`mirror_candidate`, in the order the rule prefers them on a tie.
MIRROR_FORMS: tuple[str, ...] = ("gap-step", "gap-sqrt")
#: ``"gap-step"``: a pair within this many degrees of ``th_h`` = 0 reads the mirror direction.
MIRROR_STEP_DEG = 1.0
#: ``"gap-sqrt"``: the gap (degrees) at which the term is whole (MA68's 7.5 deg).
MIRROR_FULL_DEG = 7.5


_GAPS: dict[tuple[str, tuple[str, ...]], float] = {}


def mirror_gap_deg(row: dict[str, Any]) -> float:
    """The row's mirror gap (degrees): stored by :func:`scans` since the mirror study; for an
    older row, the preset's, or the designed layout's for the row's basis (measured materials
    are held out of theirs)."""
    if "mirror_gap" in row:
        return float(row["mirror_gap"])
    design = next(d for label, d, _ in PLANS if label == row["plan"])
    exclude = (row["material"],) if row["kind"] == "measured" else ()
    key = (design, exclude if design == "posterior" else ())
    if key not in _GAPS:
        if design == "posterior":
            bu.CHOOSE["objective"] = "posterior"
            bu.SPAN["scan"] = bu.SPAN["design"] = DEFAULT_SPAN_DEG
            cells, _ = bu.design(default_basis(exclude=list(exclude)), 10)
        else:
            cells, _ = get_preset(design).cells()
        _GAPS[key] = cells_gap_deg(cells)
    return _GAPS[key]


def mirror_term(gap_deg: float, form: str, m: float) -> float:
    """The mirror gap's term (``log_rmse`` units) of ``form`` at ``m`` (module docstring)."""
    if form == "gap-step":
        return m if gap_deg > MIRROR_STEP_DEG else 0.0
    if form == "gap-sqrt":
        return m * min(1.0, float(np.sqrt(max(gap_deg, 0.0) / MIRROR_FULL_DEG)))
    raise ValueError(f"unknown form {form!r}; one of {', '.join(MIRROR_FORMS)}")


def mirror_candidate(row: dict[str, Any], form: str, m: float) -> float:
    """The estimate of a row under the mirror-gap ``form`` with parameter ``m`` (module
    docstring): the shipped mapping (highlight and under terms, the misfit and peak floors)
    with :func:`mirror_term` added as a variance beside the coverage term."""
    term = mirror_term(mirror_gap_deg(row), form, m)
    return max(final_log_rmse(row["unwidened"], row["uncovered"], row_misfit(row),
                              in_plane=term, highlight_excess=excess_of(row),
                              cv_log_under=row["cv_log_under"]),
               peak_floor(row))


#: The mirror study's fit set (module docstring).
MIRROR_FIT_SETS: tuple[str, ...] = ("cal", "fresh-wide", "fresh-coat")
#: Its check groups, each a condition (no more scans more than 2x low than shipped).
MIRROR_CHECKS: tuple[tuple[str, ...], ...] = (
    ("choice",), ("test", "fresh", "fresh-inplane", "fresh-confirm"), ("fresh-high", "fresh-cov"))
#: The most the share within x2 over every set before the blind one may fall (a fraction).
MIRROR_WITHIN_SLACK = 0.05


def mirror_study(rows: list[dict[str, Any]],
                 scan_blind: Callable[[], list[dict[str, Any]]] | None = None) -> bool | None:
    """The mirror gap, its rule committed before any candidate was computed and before any
    scan of :data:`FRESH_MIRROR` (module docstring): returns whether it is adopted, None when
    the rows lack what it needs.

    Prints, in this order: the fit over both forms, the check groups, the interval's factor,
    then fresh-mirror's blind set, which ``scan_blind`` scans (and which is appended to
    ``rows``) when ``rows`` has none of it."""
    if any("cv_log_under" not in r for r in rows):
        return None
    by = {w: [r for r in rows if r["set"] == w] for w in SETS}
    fit = [r for w in MIRROR_FIT_SETS for r in by[w]]
    shipped_ok = sum(abs(mirror_candidate(r, "gap-step", 0.0) - r["widened"])
                     <= 1e-9 * max(r["widened"], 1.0) for r in rows)
    print(f"\n#### The mirror gap (science.md 7.1.1)\n\nrows whose shipped estimate the "
          f"candidate reproduces at m = 0: {shipped_ok} of {len(rows)}")
    gaps = sorted({(r["plan"], round(mirror_gap_deg(r), 2)) for r in rows})
    print("mirror gaps (plan, degrees): " + ", ".join(f"{p} {g:g}" for p, g in gaps))
    base = _counts(fit, lambda r: r["widened"])
    print(f"\nfit on {' + '.join(MIRROR_FIT_SETS)} (shipped: {base[0]} within x2 / {base[1]} "
          f"low / {base[2]} scans)\n")
    print("| form | m | fit: within x2 / low / scans |")
    print("|---|---|---|")
    best: tuple[int, int, int, float] | None = None
    for fi, form in enumerate(MIRROR_FORMS):
        for m in MIRROR_GRID:
            w, lo, n = _counts(fit, lambda r, f=form, m=m: mirror_candidate(r, f, m))
            print(f"| {form} | {m:g} | {w} / {lo} / {n} |")
            key = (lo, -w, fi, m)
            if best is None or key < best:
                best = key
    assert best is not None
    form, m = MIRROR_FORMS[best[2]], best[3]
    print(f"\nchosen on the fit set: {form}, m = {m:g}")
    adopted = best[0] < base[1]
    if not adopted:
        print("\nno fewer low on the fit set: not adopted")

    def cand(r: dict[str, Any]) -> float:
        return mirror_candidate(r, form, m)

    print("\nfit set:")
    _compare_sets(by, MIRROR_FIT_SETS, cand)
    for names in MIRROR_CHECKS:
        print(f"\ncheck {', '.join(names)}:")
        a, b = _compare_sets(by, names, cand)
        ok = b[1] <= a[1]
        adopted = adopted and ok
        print(f"\n{', '.join(names)} rule: {'passed' if ok else 'FAILED'} (shipped {a[0]} "
              f"within x2 / {a[1]} low, candidate {b[0]} / {b[1]})")
    before = [r for w in SETS if w != "fresh-mirror" for r in by[w]]
    sw = _counts(before, lambda r: r["widened"])
    cw = _counts(before, cand)
    ok = (sw[0] - cw[0]) <= MIRROR_WITHIN_SLACK * sw[2]
    adopted = adopted and ok
    print(f"\nevery set before the blind one: shipped {sw[0]} within x2 / {sw[1]} low, "
          f"candidate {cw[0]} / {cw[1]} of {sw[2]}; within-x2 rule (a fall of at most "
          f"{MIRROR_WITHIN_SLACK:.0%}): {'passed' if ok else 'FAILED'}")
    _interval_line(by, cand)
    adopted = _blind_rule(rows, by, "fresh-mirror", cand, scan_blind) and adopted
    print(f"\nmirror gap: {'ADOPT' if adopted else 'not adopted'} ({form}, m = {m:g})")
    return adopted


def mirror_gap_table(rows: list[dict[str, Any]]) -> None:
    """The shipped estimate by the layout's mirror gap: what the note a result with a gap
    carries quotes (:data:`gonio.brdf.mirrorgap.MIRROR_GAP_LIMIT_DEG`; science.md 7.1.1.2).
    Every set, the blind ones included: a statement of what was measured, not a choice."""
    print("\n#### The shipped estimate by mirror gap (every set)\n")
    print("| plan | mirror gap (deg) | scans | within x2 | more than 2x low | worst low "
          "(true / estimate) | true above the upper end |")
    print("|---|---|---|---|---|---|---|")
    groups: dict[tuple[str, float], list[dict[str, Any]]] = {}
    for r in rows:
        groups.setdefault((r["plan"], round(mirror_gap_deg(r), 2)), []).append(r)
    for with_gap in (False, True):
        sel = [r for (_, g), rs in groups.items() if (g > MIRROR_GAP_LIMIT_DEG) == with_gap
               for r in rs]
        for (plan, g), rs in sorted(groups.items()):
            if (g > MIRROR_GAP_LIMIT_DEG) == with_gap:
                _mirror_gap_row(plan, f"{g:g}", rs)
        _mirror_gap_row(f"**every layout with a gap {'above' if with_gap else 'of at most'} "
                        f"{MIRROR_GAP_LIMIT_DEG:g} deg**", "", sel)
    lows = sorted((r for r in rows if mirror_gap_deg(r) > MIRROR_GAP_LIMIT_DEG
                   and r["truth"] / r["widened"] > 2.0),
                  key=lambda r: -r["truth"] / r["widened"])
    print("\nmore than 2x low with a gap: " + ", ".join(
        f"{r['material']} ({r['plan'].split()[0]}, {r['set']}) x{r['truth'] / r['widened']:.2f}"
        for r in lows))


def _mirror_gap_row(label: str, gap: str, rs: list[dict[str, Any]]) -> None:
    if not rs:
        return
    w, lo, n = _counts(rs, lambda r: r["widened"])
    worst = max(r["truth"] / r["widened"] for r in rs)
    above = sum(r["truth"] > r["upper"] for r in rs if np.isfinite(r.get("upper", np.nan)))
    print(f"| {label} | {gap} | {n} | {w} | {lo} | {worst:.2f} | {above} |")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--rows", type=Path, default=None,
                    help="JSON file of the scans: read it if it exists, else write it")
    ap.add_argument("--witnesses", action="store_true",
                    help="also record the standardised leave-one-pair-out error and the "
                         "posterior's scale (calibrate_log_rmse.witnesses) and print them for "
                         "the scans more than 2x too low")
    ap.add_argument("--eta", type=float, default=None,
                    help="the joint fit's eta for every scan (bench_eta.py's check; default: "
                         "reconstruct's)")
    args = ap.parse_args(argv)
    if args.eta is not None and args.witnesses:
        ap.error("--witnesses computes the default fit's witnesses (calibrate_log_rmse); "
                 "leave out --eta")
    if args.eta is not None and args.rows is not None and args.rows.is_file():
        ap.error(f"--rows {args.rows} exists and holds scans made at whatever eta wrote it; "
                 "give a new file with --eta")
    print(f"$ {' '.join(['python', *sys.argv])}")
    t0 = time.perf_counter()
    # fresh-cov is the coverage shrink's blind set: scanned only after its choice (cov_study).
    # fresh-mirror is the mirror gap's: scanned only after its choice (mirror_study).
    before_blind = tuple(w for w in SETS if w not in ("fresh-cov", "fresh-mirror"))
    if args.rows is not None and args.rows.is_file():
        rows = json.loads(args.rows.read_text())
    else:
        rows = scans(args.witnesses, args.eta, sets=before_blind)
        if args.rows is not None:
            args.rows.write_text(json.dumps(rows))

    def scan_blind(which: str = "fresh-cov") -> list[dict[str, Any]]:
        blind = scans(args.witnesses, args.eta, sets=(which,))
        for r in blind:
            r["refit"] = refit_candidate(r)
        return blind

    table(rows)
    in_plane_study(rows)
    confirm_in_plane(rows)
    highlight_cross_table(rows)
    highlight_study(rows)
    under_study(rows)
    overprediction_cross_table(rows)
    high_study(rows)
    n_rows = len(rows)
    cov_study(rows, scan_blind)
    mirror_study(rows, lambda: scan_blind("fresh-mirror"))
    mirror_gap_table(rows)
    if args.rows is not None and len(rows) > n_rows:
        args.rows.write_text(json.dumps(rows))
    print(f"total {time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
