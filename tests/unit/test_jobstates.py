"""The transition table: allowed moves pass, everything else is refused with a clear message."""

from __future__ import annotations

import itertools

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


@pytest.mark.parametrize("cur", list(JobState))
@pytest.mark.parametrize("new", list(JobState))
def test_every_pair_follows_the_table(cur: JobState, new: JobState) -> None:
    if new in TRANSITIONS[cur]:
        assert check_transition(cur, new, 7) is new
    else:
        with pytest.raises(IllegalTransition, match=f"job 7 cannot go from {cur.value}"):
            check_transition(cur, new, 7)


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
