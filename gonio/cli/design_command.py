"""``gonio design``: choose light/sensor geometry for a rig, or evaluate a preset.

Examples::

    gonio design --pairs 10 --max-elevation 75 --min-device-distance 12 -o pairs.toml
    gonio design --pairs 10 --objective posterior --candidates 4
    gonio design --lights 3 --sensors 4 --exclude cone:0,0,10 -o product.toml
    gonio design --preset MA98 --rotations 8
    gonio design --pairs 10 --colour MA98 -o pairs.toml

The design is printed (cells and lab placements), with the objective that chose it
(``--objective``: V&F's condition number or the joint fit's expected error; default
:data:`gonio.brdf.design.pairs.DEFAULT_OBJECTIVE`), its condition number, the joint fit's
expected log_rmse and the smallest roughness its plan can resolve at ``--rotations`` uniform
stage angles, and can be written as a rig-config fragment (``[[lights]]``, ``[[sensors]]`` and
the pairs) to merge into a rig config.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any, TextIO

import numpy as np

from gonio.brdf.colour.conditions import ColourError
from gonio.brdf.design.colourtargets import (
    DEFAULT_COLOUR_WEIGHT,
    MAX_COLOUR_WEIGHT,
    ColourTargets,
)
from gonio.brdf.design.constraints import RigConstraints, parse_exclusion
from gonio.brdf.design.errors import DesignError
from gonio.brdf.design.pairs import (
    DEFAULT_OBJECTIVE,
    OBJECTIVES,
    BasisLike,
    PairDesign,
    design_pairs,
    geometry_design,
    with_expected_error,
)
from gonio.brdf.design.presets import get_preset, preset_names
from gonio.brdf.design.product import design_product_rig
from gonio.brdf.design.renderweight import DEFAULT_CELL_MIX, cell_weighting
from gonio.brdf.design.roughness import RoughnessBound, bound_angles, roughness_bound
from gonio.brdf.mirrorgap import cells_gap_deg, gap_note
from gonio.brdf.reconstruction.samples import DEFAULT_SPAN_DEG, SPANS_DEG
from gonio.cli import CORE_SETTING_FLAGS, UsageError, refuse_to_replace
from gonio.sampling_design import colour_targets
from gonio.wording import counted


def register(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "design",
        help="optimize light/sensor directions (or evaluate a preset) for a rig",
        description=(
            "Choose measurement geometry under the rig's mounting limits: independent pairs by "
            "the condition number of the basis rows they sample (Vávra & Filip 2016, Sec. 3.3) "
            "or by the joint fit's expected error (--objective), product rigs by the condition "
            "number."
        ),
    )
    what = p.add_mutually_exclusive_group(required=True)
    what.add_argument("--pairs", type=int, metavar="N", help="N independent light/sensor pairs")
    what.add_argument("--lights", type=int, metavar="L",
                      help="product rig: L lights, each measured with every sensor")
    what.add_argument("--preset", metavar="NAME",
                      help=f"evaluate an industrial geometry: {', '.join(preset_names())}")
    p.add_argument("--sensors", type=int, metavar="S", help="product rig: S sensors")
    p.add_argument("--max-elevation", type=float, default=80.0, metavar="DEG",
                   help="largest device angle from the normal (default 80)")
    p.add_argument("--min-separation", type=float, default=10.0, metavar="DEG",
                   help="smallest light-sensor angle of a pair (default 10)")
    p.add_argument("--min-device-distance", type=float, default=10.0, metavar="DEG",
                   help="smallest angle between any two mounted devices (default 10); the "
                        "search only visits designs that can be mounted this way")
    p.add_argument("--exclude", action="append", default=[], metavar="REGION",
                   help="lab region without devices: cone:THETA,PHI,RADIUS or "
                        "box:THETA_MIN,THETA_MAX,PHI_MIN,PHI_MAX (degrees); repeatable")
    p.add_argument("--objective", choices=OBJECTIVES, default=None,
                   help="what chooses --pairs: kappa (the condition-number search) or "
                        "posterior (the joint fit's expected error at --rotations; falls back "
                        "to the search when its choice cannot be mounted) (default "
                        f"{DEFAULT_OBJECTIVE})")
    p.add_argument("--colour", metavar="INSTRUMENT", default=None,
                   help="for --pairs: design for colour at this instrument's geometries "
                        "(MA68, MA98, BYK-mac, MultiFX10): a pair at each near-specular one, "
                        "the others weighted toward the rest (docs/colour.md)")
    p.add_argument("--colour-weight", type=float, default=DEFAULT_COLOUR_WEIGHT, metavar="W",
                   help="with --colour: weight of the instrument geometries' expected error "
                        f"against the whole table's (default {DEFAULT_COLOUR_WEIGHT:g}; 0: only "
                        "the pairs at the near-specular geometries)")
    p.add_argument("--render-mix", type=float, default=None, metavar="A",
                   help="for --pairs by the expected error: weigh the grid's cells (1 - A) as "
                        "log_rmse does plus A as the standard renderings' pixels see them "
                        f"(0..1; default {DEFAULT_CELL_MIX:g}, the design's own; 0: weigh them "
                        "as log_rmse does alone; the response is not smooth: A = 0.25 made the "
                        "measured log_rmse +64 %% worse; --colour designs take none; a value "
                        "given here has no fallback on a crowded rig, the default has; "
                        "docs/science.md 7.2.2)")
    p.add_argument("--seed", type=int, default=0,
                   help="random seed of the kappa search; for --objective posterior it picks "
                        "the first pair the greedy choice starts from (0: the best single "
                        "pair, k: the k-th best, modulo 64) (default 0)")
    p.add_argument("--rotations", type=int, default=8, metavar="R",
                   help="uniform stage angles of the scan: for the roughness bound, the "
                        "expected log_rmse and --objective posterior (default 8)")
    p.add_argument("--span", type=float, choices=SPANS_DEG, default=DEFAULT_SPAN_DEG, metavar="DEG",
                   help="arc those angles cover: 180 (half a turn, the scans' default) or 360 "
                        "(default 180)")
    p.add_argument("--starts", type=int, default=10, help="random starts (default 10)")
    p.add_argument("--descents", type=int, default=10,
                   help="descents per start for --pairs (default 10)")
    p.add_argument("--neighbourhood", type=int, default=7, metavar="H",
                   help="odd neighbourhood size of the search (default 7)")
    p.add_argument("--time-limit", type=float, default=None, metavar="SECONDS",
                   help="stop starting new descents after this long")
    p.add_argument("--candidates", type=int, default=1, metavar="K",
                   help="for --pairs: make K designs (seeds --seed .. --seed + K - 1; for "
                        "the posterior objective K different first pairs) and keep the one "
                        "with the lowest expected error on held-out materials (default 1)")
    p.add_argument("--no-expected-error", action="store_true",
                   help="skip the held-out error estimate (it needs the default basis)")
    p.add_argument("--basis", type=Path, default=None, metavar="FILE",
                   help="basis .npz (default: the default basis, built and cached on first use)")
    p.add_argument("-o", "--output", type=Path, default=None, metavar="FILE",
                   help="write the geometry as a rig-config TOML fragment (an existing file "
                   "only with --overwrite)")
    p.add_argument("--overwrite", action="store_true", help="replace the file -o names")
    p.set_defaults(func=run)


def _constraints(args: argparse.Namespace) -> RigConstraints:
    return RigConstraints(
        max_elevation_deg=args.max_elevation,
        min_separation_deg=args.min_separation,
        min_device_distance_deg=args.min_device_distance,
        exclusions=tuple(parse_exclusion(e) for e in args.exclude),
    )


def _load_basis(path: Path | None) -> BasisLike:
    from gonio.brdf.reconstruction.basis import Basis, default_basis

    if path is None:
        return default_basis(progress=sys.stderr.isatty())
    if not path.is_file():
        raise UsageError(f"basis file {path} does not exist; give a .npz written by gonio")
    return Basis.load(path)


def _check_args(args: argparse.Namespace) -> None:
    if args.pairs is not None and args.pairs < 1:
        raise UsageError(f"--pairs must be at least 1, got {args.pairs}")
    if args.lights is not None:
        if args.sensors is None:
            raise UsageError("--lights needs --sensors (a product rig measures every pair)")
        if args.lights < 1 or args.sensors < 1:
            raise UsageError("--lights and --sensors must both be at least 1")
    elif args.sensors is not None:
        raise UsageError("--sensors goes with --lights; for independent pairs use --pairs N")
    if args.objective is not None and args.pairs is None:
        raise UsageError("--objective chooses --pairs designs; product rigs use the condition "
                         "number and presets are fixed geometries")
    if args.colour is not None:
        if args.pairs is None or args.objective == "kappa":
            raise UsageError("--colour designs --pairs by the expected error: use it with "
                             "--pairs and without --objective kappa")
        if not args.colour_weight <= MAX_COLOUR_WEIGHT:  # also refuses nan
            raise UsageError(f"--colour-weight must be between 0 and {MAX_COLOUR_WEIGHT:g}, "
                             f"got {args.colour_weight:g}")
        _colour(args)
    if args.render_mix is not None and args.render_mix != 0.0:
        if args.pairs is None or args.objective == "kappa":
            raise UsageError("--render-mix weighs the expected-error design of --pairs: use it "
                             "with --pairs and without --objective kappa")
        if not 0.0 <= args.render_mix <= 1.0:
            raise UsageError(f"--render-mix must be between 0 and 1, got {args.render_mix:g}")
        if args.colour is not None:
            raise UsageError("--render-mix and --colour cannot be combined (each reweighs the "
                             "expected error; together the scales are wrong): use one")
    if args.seed < 0:
        raise UsageError(f"--seed must be at least 0, got {args.seed}")
    if args.rotations < 1:
        raise UsageError(f"--rotations must be at least 1, got {args.rotations}")
    if args.neighbourhood < 1 or args.neighbourhood % 2 == 0:
        raise UsageError(f"--neighbourhood must be an odd number >= 1, got {args.neighbourhood}")
    if args.starts < 1 or args.descents < 1:
        raise UsageError("--starts and --descents must be at least 1")
    if args.candidates < 1:
        raise UsageError(f"--candidates must be at least 1, got {args.candidates}")
    if args.candidates > 1 and (args.pairs is None or args.basis is not None
                                or args.no_expected_error):
        raise UsageError("--candidates chooses among --pairs designs by their expected error on "
                         "held-out materials: it needs --pairs and the default basis")


def _colour(args: argparse.Namespace) -> ColourTargets | None:
    """The colour targets ``--colour`` asks for (UsageError for a bad name or weight)."""
    if getattr(args, "colour", None) is None:
        return None
    try:
        return colour_targets(args.colour, args.colour_weight)
    except (ColourError, DesignError) as exc:
        raise UsageError(f"--colour / --colour-weight: {exc}") from None


def _colour_record(args: argparse.Namespace, design: PairDesign) -> dict[str, Any]:
    """The ``[design]`` keys of a colour design (none without ``--colour``) and the
    ``render_mix`` of a rendering-weighted one (``design.cell_mix``; none at 0)."""
    mix = float(design.cell_mix)
    if getattr(args, "colour", None) is None:
        return {"render_mix": mix} if mix else {}
    from gonio.brdf.colour.instruments import canonical_instrument

    return {"colour_instrument": canonical_instrument(args.colour),
            "colour_weight": float(args.colour_weight)}


def make_design(args: argparse.Namespace, basis: BasisLike) -> PairDesign:
    """The design the arguments ask for (optimized pairs, product rig or preset)."""
    if args.preset is not None:
        preset = get_preset(args.preset)
        wi, wo = preset.directions()
        n = preset.n_pairs
        fixed = geometry_design(basis, preset.name, wi, wo, np.stack([np.arange(n)] * 2, axis=1))
        return with_expected_error(basis, fixed, args.rotations, args.span)
    constraints = _constraints(args)
    if args.lights is not None:
        return with_expected_error(basis, design_product_rig(
            basis, args.lights, args.sensors, constraints, h=args.neighbourhood,
            starts=args.starts, seed=args.seed, time_limit_s=args.time_limit,
        ), args.rotations, args.span)
    return design_pairs(
        basis, args.pairs, constraints, h=args.neighbourhood, starts=args.starts,
        descents=args.descents, seed=args.seed, time_limit_s=args.time_limit,
        objective=args.objective, rotations=args.rotations, span_deg=args.span,
        colour=_colour(args), **_render_mix(args),
    )


def _render_mix(args: argparse.Namespace) -> dict[str, Any]:
    """``design_pairs``' cell weighting for ``--render-mix`` (none given: the default)."""
    return cell_weighting(getattr(args, "render_mix", None))


SINGULAR_KAPPA = 1e6
"""Above this condition number the design gets an explanation of what makes it singular."""
#: A render-weighted design whose pairs all sit at least this far from light and view
#: together (their difference angle ``td``, degrees) reads a broad retro-reflective lobe
#: poorly: the renderings see ``td`` only at 10, 27.5 and 35 degrees, and on the library's
#: held-out synthetic retro-reflectors (broad lobes) the weighted default read +82 %
#: ``log_rmse`` against the unweighted design, whose pairs reached ``td`` 5-10
#: (docs/notes/2026-11-27-wide-panel-rise.md).
RETRO_TD_DEG = 15.0


def explain_condition(design: PairDesign, rotations: int,
                      span_deg: float = 360.0) -> list[str]:
    """Why a design's condition number is infinite (or huge), and what that means for a scan.

    Pairs whose half/difference cells coincide sample the same basis row (the pair's lab
    azimuth does not enter the row), so the rows are linearly dependent. Pairs at the same
    ``(th, td)`` with ``pd`` and ``180 - pd`` are mirror images, which a basis learned from
    materials that are nearly mirror-symmetric barely tells apart.

    Returns
    -------
    list of str
        Lines to print; empty when the condition number is below :data:`SINGULAR_KAPPA`.
    """
    if design.kappa < SINGULAR_KAPPA:
        return []
    deg = np.rad2deg(design.cells)
    n = design.n_pairs
    lines = []
    same: list[tuple[int, int]] = []
    mirror: list[tuple[int, int]] = []
    for i in range(n):
        for j in range(i + 1, n):
            close_thd = np.allclose(deg[i, :2], deg[j, :2], atol=1e-6)
            if close_thd and abs(deg[i, 2] - deg[j, 2]) < 1e-6:
                same.append((i, j))
            elif close_thd and abs(deg[i, 2] + deg[j, 2] - 180.0) < 1e-6:
                mirror.append((i, j))
    for i, j in same:
        c = deg[i]
        lines.append(f"  why: pairs {i + 1} and {j + 1} sample the same cell (th {c[0]:.1f}, "
                     f"td {c[1]:.1f}, pd {c[2]:.1f} deg): their basis rows are equal, so the "
                     "rows are linearly dependent and the smallest singular value is 0")
    if mirror:
        listed = ", ".join(f"{i + 1}/{j + 1}" for i, j in mirror)
        lines.append(f"  also: pairs {listed} are mirror images (pd and 180 - pd at the same "
                     "th, td), which the basis barely tells apart")
    if not lines:
        lines.append("  why: the pairs' basis rows are (nearly) linearly dependent: some pairs "
                     "repeat what others measure")
    distinct = n - len({j for _, j in same})
    # Uniform angles over the arc reach a pair's azimuths modulo the arc (a twofold-symmetric
    # specimen reads the same half a turn on), so two pairs in one cell repeat each other when
    # their lab azimuths differ by a multiple of the step.
    step = span_deg / rotations
    repeats = [
        (i, j) for i, j in same
        if min(d := float(np.rad2deg(design.ph_lab[i] - design.ph_lab[j])) % step,
               step - d) < 1e-6
    ]
    lines.append(
        f"  for a scan: the regularized solve still reconstructs a BRDF (regularization fills "
        f"what the rows leave open), but these {n} pairs sample at most {distinct} distinct "
        "cells; a pair in another's cell adds only the specimen azimuths its lab azimuth "
        "reaches"
    )
    for i, j in repeats:
        lines.append(f"  at {rotations} uniform rotations over {span_deg:g} deg pairs {i + 1} "
                     f"and {j + 1} reach the "
                     "same specimen azimuths: they repeat each other's readings (which only "
                     "averages noise)")
    return lines


def print_design(
    design: PairDesign, bound: RoughnessBound, rotations: int, out: TextIO | None = None,
    span_deg: float = DEFAULT_SPAN_DEG,
) -> None:
    """Human-readable table of the design, its condition number and roughness bound."""
    out = sys.stdout if out is None else out
    print(f"design: {design.name}, {counted(design.n_pairs, 'pair')}", file=out)
    print(
        f"{'pair':>4} {'th':>6} {'td':>6} {'pd':>6} | {'theta_i':>7} {'phi_i':>6} "
        f"{'theta_v':>7} {'phi_v':>6}   (degrees)",
        file=out,
    )
    cells = np.rad2deg(design.cells)
    for k, (c, lab) in enumerate(zip(cells, design.lab_deg, strict=True)):
        print(
            f"{k + 1:>4} {c[0]:6.1f} {c[1]:6.1f} {c[2]:6.1f} | {lab[0]:7.1f} {lab[1] % 360:6.1f} "
            f"{lab[2]:7.1f} {lab[3] % 360:6.1f}",
            file=out,
        )
    if design.objective is not None:
        print(f"objective: {design.objective} ("
              + ("condition-number search" if design.objective == "kappa"
                 else "joint fit's expected error") + ")", file=out)
    if design.fallback is not None:
        # Worded with the flags this command takes, as its errors are (gonio.cli).
        print(f"  note: {design.fallback_for(CORE_SETTING_FLAGS)}", file=out)
    if design.colour_pairs:
        print(f"colour: pairs 1-{design.colour_pairs} sit at the instrument's near-specular "
              "geometries; the colour report reads those from the scan (docs/colour.md)",
              file=out)
    expected = ""
    if design.expected_log_rmse is not None:
        arc = "" if design.span_deg is None else f" over {design.span_deg:g} deg"
        expected = (f", expected log_rmse {design.expected_log_rmse:.4f} at "
                    f"{design.rotations} rotations{arc} (inside the basis: on the materials it "
                    "was learnt from, a best case, not a prediction for a new specimen)")
    print(f"condition number: {design.kappa:.4g}{expected}", file=out)
    for line in explain_condition(design, rotations, span_deg):
        print(line, file=out)
    print(f"closest two devices: {design.min_distance_deg:.1f} deg", file=out)
    # What the layout can never read, whatever the stage angles (gonio.brdf.mirrorgap): a
    # scan's result states the same, after the fact.
    gap = cells_gap_deg(design.cells)
    print(f"mirror gap: {gap:.1f} deg (the least th: no stage angle reads nearer the mirror "
          "direction)", file=out)
    if (note := gap_note(gap)) is not None:
        print(f"  glossy specimens: {note}", file=out)
    if design.search is not None:
        s = design.search
        print(f"search: {s.neighbourhoods} neighbourhoods, {s.evaluations} candidates, "
              f"{s.seconds:.1f} s", file=out)
    if design.greedy is not None:
        g = design.greedy
        print(f"greedy choice: {g.candidates} cells scored per pair ({g.evaluations} in all), "
              f"{g.mount_checks} mount checks, first pair rank {g.first}, {g.seconds:.1f} s",
              file=out)
    print(
        f"roughness bound at {rotations} rotations over {span_deg:g} deg: "
        f"alpha' = {bound.alpha_min:.3g} "
        f"(N = {bound.n_effective:.0f} effective samples within {bound.cap_deg:g} deg of the "
        f"normal, l* = {bound.degree})",
        file=out,
    )


ASSUMPTIONS = (
    "what it assumes: a calibrated scan (1/sr) with 1 % reading noise, uniform stage angles, "
    "the default joint reconstruction;",
    "the held-out number is the mean over materials left out of the basis (the shipped "
    "measured ones and one synthetic of each family): set a scan's predicted_log_rmse (its own "
    "estimate of the same log_rmse) beside it, not the inside-the-basis one;",
    "a specimen unlike that panel (strongly anisotropic, very glossy) or an uncalibrated scan "
    "can read two or more times higher.",
)
"""What the design's expected errors assume, printed under them (issue 27: a design promising
0.012 'inside the basis' beside a scan reporting 0.058 on an anisotropic material)."""


def run(args: argparse.Namespace) -> int:
    _check_args(args)
    refuse_to_replace(args.output, args.overwrite, "nothing was designed")
    _constraints(args)  # refuse bad limits and --exclude text before the (slow) basis load
    basis = _load_basis(args.basis)
    expected = None
    if args.candidates > 1:
        from gonio.brdf.design.heldout import choose_design

        constraints = _constraints(args)
        colour, mix = _colour(args), _render_mix(args)  # the importance map once, not per seed

        def make(seed: int) -> PairDesign:
            return design_pairs(
                basis, args.pairs, constraints, h=args.neighbourhood, starts=args.starts,
                descents=args.descents, seed=args.seed + seed, time_limit_s=args.time_limit,
                objective=args.objective, rotations=args.rotations, span_deg=args.span,
                colour=colour, **mix,
            )

        design, expected, table = choose_design(make, range(args.candidates), args.rotations,
                                                span_deg=args.span)
        print(f"{len(table)} candidate designs (seed, kappa, expected log_rmse on held-out "
              "materials):")
        for seed, kappa, err in table:
            print(f"  seed {args.seed + seed}: kappa {kappa:.4g}, expected log_rmse {err:.4f}")
    else:
        design = make_design(args, basis)
    bound = roughness_bound(design.cells, design.ph_lab, bound_angles(args.rotations, args.span))
    print_design(design, bound, args.rotations, span_deg=args.span)
    if design.cell_mix:
        print(f"cells weighted by the standard renderings at {design.cell_mix:g} "
              "(--render-mix; docs/science.md 7.2.2)")
        closest = float(np.degrees(np.min(np.asarray(design.cells)[:, 1])))
        if closest >= RETRO_TD_DEG - 1e-6:
            print(f"retro-reflection: the closest pair has light and view {2 * closest:.0f} "
                  f"degrees apart (difference angle td {closest:.1f} degrees), so a broad "
                  "retro-reflective lobe is read poorly; for such specimens try --render-mix "
                  "0 (docs/design.md)")
    if args.basis is None and not args.no_expected_error and args.lights is None:
        if expected is None:
            from gonio.brdf.design.heldout import heldout_log_rmse, panel_is_cached

            if not panel_is_cached():
                # The first run builds the held-out panel: say why it is quiet for a while.
                print("expected error: building the held-out panel's bases from the training "
                      "library (first use only; about half a minute and 3.5 GB of memory; "
                      "--no-expected-error skips it)", file=sys.stderr, flush=True)
            expected = heldout_log_rmse(design.cells, design.ph_lab, args.rotations,
                                         span_deg=args.span)
        print(f"expected log_rmse on held-out materials at {args.rotations} rotations over "
              f"{args.span:g} deg: "
              f"{expected.log_rmse:.4f} (measured {expected.measured:.4f}, synthetic "
              f"{expected.synthetic:.4f}; lower is better, next to kappa {design.kappa:.4g})")
        for line in ASSUMPTIONS:
            print(f"  {line}")
    if args.output is not None:
        from gonio.rigdesign import design_fragment, dump_fragment

        args.output.parent.mkdir(parents=True, exist_ok=True)
        held_out = ("" if expected is None else
                    f"\nExpected log_rmse on held-out materials {expected.log_rmse:.4f} at "
                    f"{args.rotations} uniform rotations over {args.span:g} deg, 1 % noise, "
                    "calibrated: compare a scan's predicted_log_rmse with this.")
        header = (f"gonio design fragment: {design.name}, {design.n_pairs} pairs, condition "
                  f"number {design.kappa:.4g}.{held_out}\nMerge it into a rig config with "
                  f"'gonio rig apply-design {args.output.name} rig.toml' (docs/rig-config.md).")
        expectation = None
        if expected is not None:
            from gonio.brdf.design.heldout import HELDOUT_NOISE
            from gonio.config import DesignExpectation

            # What a scan's predicted_log_rmse is compared with when it finishes
            # (gonio.designgap), with what the number assumes.
            expectation = DesignExpectation(
                expected_log_rmse=round(expected.log_rmse, 5),
                expected_log_rmse_measured=round(expected.measured, 5),
                expected_log_rmse_synthetic=round(expected.synthetic, 5),
                inside_basis_log_rmse=(
                    round(float(design.expected_log_rmse), 5)
                    if design.expected_log_rmse is not None
                    and np.isfinite(design.expected_log_rmse) else None),
                rotations=args.rotations, span_deg=args.span, noise=HELDOUT_NOISE,
                pairs=design.n_pairs, calibrated=True, **_colour_record(args, design),
            )
        elif _colour_record(args, design):
            from gonio.config import DesignExpectation

            # No held-out error to compare scans with, but the rig config still records
            # that its geometry is a colour design (its scans report that instrument) or a
            # rendering-weighted one.
            expectation = DesignExpectation(rotations=args.rotations, span_deg=args.span,
                                            pairs=design.n_pairs, **_colour_record(args, design))
        args.output.write_text(dump_fragment(design_fragment(design, expectation), header),
                               encoding="utf-8")
        print(f"wrote {args.output}; merge it with 'gonio rig apply-design {args.output} "
              "rig.toml'")
    return 0
