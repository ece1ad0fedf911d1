"""The transition table: allowed moves pass, everything else is refused with a clear message."""

from __future__ import annotations

import itertools
import re
from pathlib import Path

import pytest

from gonio.jobstates import (
    ACTIONS,
    FINISHED_STATES,
    TRANSITIONS,
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


def test_finished_states_are_terminal() -> None:
    for s in FINISHED_STATES:
        assert not TRANSITIONS[s]


@pytest.mark.parametrize("action", sorted(ACTIONS))
def test_actions_refused_outside_their_states(action: str) -> None:
    for s in JobState:
        if s in ACTIONS[action]:
            check_action(action, s, 3)
        else:
            with pytest.raises(IllegalTransition) as exc:
                check_action(action, s, 3)
            assert f"cannot {action} job 3: it is {s.value}" in str(exc.value)
            assert exc.value.state == s.value
