"""What a result says of its arc (gonio.arc_wording): who chose it, by the words' own rules."""

from __future__ import annotations

from gonio.arc_wording import arc_fixed_by_plan, arc_sentence, arc_summary_line, p_value_text

TEST = {"arc_test_statistic": 37.31, "arc_test_dof": 216, "arc_test_p_value": 1.0}


def test_an_auto_arc_says_the_test_chose_it() -> None:
    sym = {**TEST, "arc_mode": "auto", "arc_symmetric": True, "arc_deg": 180.0}
    assert not arc_fixed_by_plan(sym)
    assert arc_sentence(sym) == ("Scanned over half a turn: the first round's readings at "
                                 "opposite stage angles say the specimen is twofold symmetric "
                                 "(chi-square 37.3 on 216 degrees of freedom, p > 0.999).")
    assert arc_summary_line(sym) == ("  arc: 180 deg; the first round read the specimen twofold "
                                     "symmetric (chi-square 37.3 on 216 degrees of freedom, "
                                     "p > 0.999)")
    asym = {**sym, "arc_symmetric": False, "arc_deg": 360.0}
    assert arc_sentence(asym).startswith("Scanned over a full turn: the first round's readings")
    assert "NOT twofold symmetric" in arc_summary_line(asym)


def test_a_fixed_arc_says_the_plan_chose_it_whatever_the_verdict() -> None:
    for symmetric, verdict in ((True, "twofold symmetric"), (False, "not twofold symmetric")):
        m = {**TEST, "arc_mode": "fixed", "arc_symmetric": symmetric, "arc_deg": 360.0}
        assert arc_fixed_by_plan(m)
        assert arc_sentence(m) == (f"Scanned over a full turn, as its plan fixed it; its "
                                   f"readings at opposite stage angles say the specimen is "
                                   f"{verdict} (chi-square 37.3 on 216 degrees of freedom, "
                                   "p > 0.999).")
        assert arc_summary_line(m).startswith("  arc: 360 deg (the plan's); its readings")


def test_a_result_without_arc_mode_is_judged_by_its_arc_and_verdict() -> None:
    """Older results: the test picks half a turn for a symmetric specimen and a full turn
    otherwise, so an arc against the verdict was the plan's; one along it reads as before."""
    assert arc_fixed_by_plan({"arc_symmetric": True, "arc_deg": 360.0})
    assert arc_fixed_by_plan({"arc_symmetric": False, "arc_deg": 180.0})
    assert not arc_fixed_by_plan({"arc_symmetric": True, "arc_deg": 180.0})
    assert not arc_fixed_by_plan({"arc_symmetric": False, "arc_deg": 360.0})
    assert not arc_fixed_by_plan({})


def test_a_p_value_is_never_printed_as_exactly_one_or_zero() -> None:
    """A chi-square of 6.5 on 36 degrees of freedom printed "p = 1" (a review); a finite
    sample's p is never exactly 1 or 0, so the ends are bounds."""
    assert p_value_text(1.0) == "p > 0.999"
    assert p_value_text(0.9995) == "p > 0.999"
    assert p_value_text(0.999) == "p = 0.999"
    assert p_value_text(0.0312) == "p = 0.0312"
    assert p_value_text(0.001) == "p = 0.001"
    assert p_value_text(2e-9) == "p < 0.001"
