"""The transition table: allowed moves pass, everything else is refused with a clear message."""

from __future__ import annotations

import itertools
import re
from pathlib import Path

import pytest

from gonio.jobstates import (
    ACTIONS,
    FINISHED_STATES,
    IllegalTransition,
    JobState,
    check_action,
    check_transition,
)

# The lifecycle as docs/architecture.md draws it, written out edge by edge here (not read from
# gonio.jobstates), so a change to the table that the documentation does not make fails.
DOCUMENTED_LIFECYCLE = """
queued -> running
running -> paused
paused -> running
running -> suspended
suspended -> running
suspended -> paused
running -> reconstructing
reconstructing -> completed
queued -> failed
running -> failed
paused -> failed
suspended -> failed
reconstructing -> failed
queued -> aborted
running -> aborted
paused -> aborted
suspended -> aborted
reconstructing -> aborted
running -> halted
paused -> halted
suspended -> halted
failed -> completed
aborted -> completed
"""
ALLOWED = {tuple(line.split(" -> ")) for line in DOCUMENTED_LIFECYCLE.strip().splitlines()}


@pytest.mark.parametrize("cur", [s.value for s in JobState])
@pytest.mark.parametrize("new", [s.value for s in JobState])
def test_every_pair_follows_the_documented_lifecycle(cur: str, new: str) -> None:
    if (cur, new) in ALLOWED:
        assert check_transition(cur, new, 7) is JobState(new)
    else:
        with pytest.raises(IllegalTransition, match=f"job 7 cannot go from {cur}"):
            check_transition(cur, new, 7)


def test_the_architecture_page_draws_the_same_lifecycle() -> None:
    """Each line of the page's lifecycle block expands to edges of ALLOWED, and back."""
    page = (Path(__file__).resolve().parents[2] / "docs" / "architecture.md").read_text()
    block = page.split("## Job lifecycle", 1)[1].split("```", 2)[1]
    drawn: set[tuple[str, str]] = set()
    for line in block.strip().splitlines():
        tokens = re.split(r"\s*(<->|->)\s*", line.split("(")[0].strip())
        groups, arrows = tokens[0::2], tokens[1::2]
        for left, arrow, right in zip(groups[:-1], arrows, groups[1:], strict=True):
            for a in left.split("|"):
                for b in right.split("|"):
                    drawn.add((a.strip(), b.strip()))
                    if arrow == "<->":
                        drawn.add((b.strip(), a.strip()))
    assert drawn == ALLOWED


def test_lifecycle_of_the_architecture() -> None:
    path = ["queued", "running", "paused", "running", "suspended", "running",
            "reconstructing", "completed"]
    for a, b in itertools.pairwise(path):
        check_transition(a, b)


# The user actions and the states they are accepted in, as docs/engine.md ("Job states") words
# them, written out here so the test does not check ACTIONS against itself.
DOCUMENTED_ACTIONS = {
    "pause": {"running", "suspended"},
    "resume": {"paused"},
    "abort": {"queued", "running", "paused", "suspended", "reconstructing"},
    "cancel": {"queued"},
    "reorder": {"queued"},
    "remove": {"queued", "completed", "failed", "aborted", "halted"},
}
FINISHED = {"completed", "failed", "aborted", "halted"}  # no job runs again from these
# The edges out of them: gonio jobs rebuild completes a job failed or aborted while it was
# being finished, every reading stored (it measures nothing).
REBUILT = {("failed", "completed"), ("aborted", "completed")}


def test_finished_states_are_terminal() -> None:
    assert {s.value for s in FINISHED_STATES} == FINISHED
    assert {a for a, _ in ALLOWED - REBUILT}.isdisjoint(FINISHED)
    for s in FINISHED:
        for new in JobState:
            if (s, new.value) in REBUILT:
                continue
            reachable = "completed" if s in ("failed", "aborted") else "no state"
            with pytest.raises(IllegalTransition, match=f"from {s} it can go to: {reachable}"):
                check_transition(s, new.value)


def test_the_actions_are_the_documented_ones() -> None:
    assert set(ACTIONS) == set(DOCUMENTED_ACTIONS)


@pytest.mark.parametrize("action", sorted(DOCUMENTED_ACTIONS))
def test_actions_refused_outside_their_states(action: str) -> None:
    for s in JobState:
        if s.value in DOCUMENTED_ACTIONS[action]:
            check_action(action, s, 3)
        else:
            with pytest.raises(IllegalTransition) as exc:
                check_action(action, s, 3)
            assert f"cannot {action} job 3: it is {s.value}" in str(exc.value)
            assert exc.value.state == s.value


def test_the_refusal_names_the_states_that_are_allowed() -> None:
    with pytest.raises(IllegalTransition,
                       match="pause is allowed only when the job is running, suspended"):
        check_action("pause", "queued", 1)
    with pytest.raises(IllegalTransition,
                       match="from paused it can go to: aborted, failed, halted, running"):
        check_transition("paused", "completed", 1)


def test_an_unknown_state_is_refused() -> None:
    with pytest.raises(ValueError, match="'finished' is not a valid JobState"):
        check_transition("finished", "queued")
