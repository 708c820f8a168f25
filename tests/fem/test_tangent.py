"""The kept factorisation and Newton's steps with it: conjugate gradients where the kept
factorisation still preconditions the current tangent, a fresh factorisation where it does not,
and a fresh one asked for at the next step where CG was slow or failed.
"""

import numpy as np
import scipy.sparse as sp

from fem.linear_solvers import make_linear_solver
from fem.tangent import Tangent

N = 400
LAPLACIAN = sp.diags([-1.0, 2.0, -1.0], [-1, 0, 1], shape=(N, N)).tocsr()


def _kept(K: sp.csr_matrix, current: sp.csr_matrix) -> Tangent:
    """A tangent that has factorised ``K`` and whose solver now assembles ``current``."""
    tangent = Tangent(make_linear_solver("superlu"), lambda u, f, definite: (None, current), False)
    assert tangent.factorise(None, None, K=K) is None
    return tangent


def _rhs() -> np.ndarray:
    return np.random.default_rng(0).normal(size=(N, 1))


def test_a_step_on_the_kept_factorisation_s_own_tangent_takes_cg_and_is_exact():
    tangent = _kept(LAPLACIAN, LAPLACIAN)
    x, failure, fresh, slow = tangent.steps(None, None, _rhs(), False, True, LAPLACIAN)
    assert failure is None and not fresh and not slow
    np.testing.assert_allclose(LAPLACIAN @ x, _rhs(), atol=1e-9)


def test_a_step_whose_cg_converges_slowly_asks_for_a_fresh_factorisation_next():
    shifted = (LAPLACIAN + sp.diags(0.03 * np.random.default_rng(1).uniform(size=N))).tocsr()
    tangent = _kept(LAPLACIAN, shifted)
    x, failure, fresh, slow = tangent.steps(None, None, _rhs(), False, True, shifted)
    assert failure is None and not fresh and slow
    residual = np.linalg.norm(shifted @ x - _rhs()) / np.linalg.norm(_rhs())
    assert residual <= 1e-3  # CG's own tolerance (an inexact Newton step)


def test_a_step_whose_cg_fails_is_solved_by_a_fresh_factorisation_and_the_next_step_too():
    """Where CG does not converge within its iterations the step factorises the current
    tangent and solves with it exactly; the tangent is moving fast there, so the next step is
    asked to factorise afresh as well.
    """
    tangent = _kept(sp.identity(N, format="csr"), LAPLACIAN)  # a kept factorisation far off
    x, failure, fresh, slow = tangent.steps(None, None, _rhs(), False, True, LAPLACIAN)
    assert failure is None and fresh and slow
    np.testing.assert_allclose(LAPLACIAN @ x, _rhs(), atol=1e-8)
    x, failure, fresh, slow = tangent.steps(None, None, 2 * _rhs(), False, True, LAPLACIAN)
    assert failure is None and not fresh and not slow  # CG on the fresh one: at once
    np.testing.assert_allclose(LAPLACIAN @ x, 2 * _rhs(), atol=1e-8)
