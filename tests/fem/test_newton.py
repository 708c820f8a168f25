"""Newton's line search: the first halving that lowers the energy enough, or none."""

import numpy as np

from fem.newton import HALVINGS, backtrack


def test_backtrack_halves_an_overshooting_step_to_the_first_that_lowers_the_energy_enough():
    """``E(x) = (x - 1)^2`` from 0 along a step of 5 (slope -10): the full step and the half
    overshoot (E 16 and 2.25, against about 1 asked), the quarter lands near the minimum.
    """
    calls = []

    def energy_at(alpha):
        calls.append(alpha)
        return (5.0 * alpha - 1.0) ** 2

    alpha, E = backtrack(energy_at, 1.0, -10.0)
    assert (alpha, E) == (0.25, 0.0625)
    assert calls == [1.0, 0.5, 0.25]  # last called at the step it returns


def test_backtrack_takes_a_step_that_keeps_the_energy_within_its_round_off():
    """Near equilibrium the energy's change is round-off: a step that leaves it equal is taken."""
    assert backtrack(lambda a: 1.0, 1.0, -1e-20) == (1.0, 1.0)


def test_backtrack_gives_up_where_no_step_is_finite():
    alpha, E = backtrack(lambda a: np.inf, 1.0, -1.0)
    assert E is None and alpha == 0.5**HALVINGS
