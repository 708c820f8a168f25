"""Newton's line search (the first halving that lowers the energy enough, or none), and its
answers checked for stability.
"""

from types import SimpleNamespace

import numpy as np
import pytest

from fem.newton import HALVINGS, backtrack, newton


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


class _Stalled:
    """A solver whose first Newton step (taken without the pressure stiffness) lowers the
    energy and whose second finds no step that does, at a residual under the round-off floor
    (a contact's nodes on the edge of touching); its full tangent there is indefinite.
    """

    def __init__(self):
        self.options = SimpleNamespace(max_iter=10, rtol=1e-12, stagnation=5, reuse=0.5)
        self.free = np.arange(3)
        self.linear = SimpleNamespace(direct=False)
        self.potentials = []
        self.residuals = iter([np.array([1.0, 0, 0]), np.array([1e-5, 0, 0])])
        self.energies = iter([1.0, 0.5])  # at the start, then at the first step's full length
        self.checked = []
        solver = self

        class Tangent:
            factored = None

            def direction(self, u, f, rf, refresh, conjugate):
                self.factored = "definite"
                return -rf, None, True, False

            def factorise(self, u, f):
                solver.checked.append(u.copy())
                return "indefinite tangent: the layer buckles", 1

        self.tangent = Tangent()

    def residual(self, u, f):
        return next(self.residuals).reshape(-1, 3)

    def energy(self, u, f):
        return next(self.energies, 2.0)  # every later step raises it


def test_an_answer_at_the_round_off_floor_is_checked_for_stability():
    """Reached with steps that left out the pressure stiffness, an answer the line search ends
    at the floor is checked against the full tangent like any other (and failed here as
    buckled); a start on the way to an answer (``check=False``) is not, and says so.
    """
    f = np.ones((1, 3))
    solver = _Stalled()
    out = newton(solver, np.zeros((1, 3)), f, floor=1e-4)
    assert not out["ok"] and out["reason"] == "indefinite tangent at the answer: the layer buckles"
    assert len(solver.checked) == 1
    solver = _Stalled()
    out = newton(solver, np.zeros((1, 3)), f, floor=1e-4, check=False)
    assert out["ok"] and out["definite"] and not solver.checked
    assert out["residual"] == pytest.approx(1e-5 / np.sqrt(3))
