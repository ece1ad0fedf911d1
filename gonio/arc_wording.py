"""What a result says of the arc it was scanned over and of its twofold symmetry test.

A scan whose readings hold opposite stage angles is tested for twofold symmetry (docs/science.md
7.4) whatever its plan: an auto-arc plan chooses its arc by the test, a fixed one only reports
it. The words must not mix the two: a scan fixed over a full turn read "Scanned over half a
turn: the first round's readings ... say the specimen is twofold symmetric" on the page, in
``gonio jobs wait`` and in the headline, because the wording looked at the verdict alone. The
result's headline (:func:`gonio.figures.headline_error`) and the terminal's summary
(:mod:`gonio.cli.scan_report`) both take their words from here.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any


def arc_fixed_by_plan(metrics: Mapping[str, Any]) -> bool:
    """Whether the result's arc was its plan's, not the test's choice.

    ``arc_mode`` says so (``"fixed"`` or ``"auto"``). A result finished before it was recorded
    is judged by its arc and verdict: the test chooses half a turn for a symmetric specimen and
    a full turn otherwise, so an arc that disagrees with the verdict was the plan's (one that
    agrees cannot be told apart and reads as the test's choice, as it did).
    """
    mode = metrics.get("arc_mode")
    if mode in ("fixed", "auto"):
        return bool(mode == "fixed")
    arc, symmetric = metrics.get("arc_deg"), metrics.get("arc_symmetric")
    return (isinstance(arc, int | float) and isinstance(symmetric, bool)
            and (arc >= 360.0) == symmetric)


def _arc_words(arc_deg: float) -> str:
    if arc_deg == 180.0:
        return "half a turn"
    return "a full turn" if arc_deg >= 360.0 else f"{arc_deg:g} degrees"


def p_value_text(p: float) -> str:
    """A test's p-value as a reader should see it: ``p = 0.031``, or ``p > 0.999`` and
    ``p < 0.001`` at the ends (a chi-square far below its degrees of freedom printed
    ``p = 1``, which no finite sample gives)."""
    if p > 0.999:
        return "p > 0.999"
    if p < 0.001:
        return "p < 0.001"
    return f"p = {p:.3g}"


def _evidence(metrics: Mapping[str, Any]) -> str:
    return (f"chi-square {metrics.get('arc_test_statistic', float('nan')):.1f} on "
            f"{metrics.get('arc_test_dof')} degrees of freedom, "
            f"{p_value_text(metrics['arc_test_p_value'])}")


def arc_sentence(metrics: Mapping[str, Any]) -> str:
    """The headline's sentence on the arc (the result's metrics hold ``arc_symmetric`` and
    ``arc_test_p_value``): which arc was scanned, who chose it, and the test's verdict."""
    symmetric = bool(metrics["arc_symmetric"])
    verdict = "twofold symmetric" if symmetric else "not twofold symmetric"
    if arc_fixed_by_plan(metrics):
        arc = _arc_words(float(metrics.get("arc_deg", 180.0)))
        return (f"Scanned over {arc}, as its plan fixed it; its readings at opposite stage "
                f"angles say the specimen is {verdict} ({_evidence(metrics)}).")
    arc = "half a turn" if symmetric else "a full turn"
    return (f"Scanned over {arc}: the first round's readings at opposite stage angles say the "
            f"specimen is {verdict} ({_evidence(metrics)}).")


def arc_summary_line(summary: Mapping[str, Any]) -> str:
    """The terminal summary's line on the arc (``gonio scan``, ``gonio jobs wait``), from the
    job's summary (the result's metrics)."""
    verdict = "twofold symmetric" if summary.get("arc_symmetric") else "NOT twofold symmetric"
    arc = summary.get("arc_deg", 0)
    if arc_fixed_by_plan(summary):
        return (f"  arc: {arc:g} deg (the plan's); its readings at opposite stage angles read "
                f"the specimen {verdict} ({_evidence(summary)})")
    return (f"  arc: {arc:g} deg; the first round read the specimen {verdict} "
            f"({_evidence(summary)})")
