"""The move-completion poll schedule shared by the stage drivers (gonio.drivers._arrival)."""

from __future__ import annotations

import pytest

from gonio.drivers._arrival import FINE_POLL_S, poll_delay


def test_poll_delay_is_coarse_then_exact_then_fine() -> None:
    end = 10.0
    assert poll_delay(9.0, end, 0.02) == 0.02  # well before the end
    assert poll_delay(9.99, end, 0.02) == pytest.approx(0.01)  # wake at the predicted end
    assert poll_delay(10.0, end, 0.02) == FINE_POLL_S
    assert poll_delay(10.5, end, 0.02) == FINE_POLL_S  # slower than predicted: keep fine
    assert poll_delay(9.0, None, 0.02) == 0.02  # no prediction (homing)
    assert poll_delay(9.0, end, 0.001) == 0.001  # a coarse interval below fine wins
