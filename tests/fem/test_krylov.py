"""Preconditioned conjugate gradients: exact on symmetric positive definite systems, and a
failure that says why elsewhere.
"""

import numpy as np
import pytest
import scipy.sparse as sp

from fem import krylov
from fem.krylov import BLOCK, pcg, symmetric_matvec


def _spd(n, seed=0):
    rng = np.random.default_rng(seed)
    B = sp.random(n, n, density=0.05, random_state=rng)
    return (B @ B.T + sp.identity(n) * 0.5).tocsr()


def test_symmetric_matvec_from_the_upper_triangle_is_the_whole_product(monkeypatch):
    A = _spd(60)
    x = np.random.default_rng(1).normal(size=60)
    assert krylov._upper_kernel() is not None, "numba is missing: the kernel cannot be checked"
    np.testing.assert_allclose(symmetric_matvec(sp.triu(A).tocsr(), True)(x), A @ x, rtol=1e-12)
    np.testing.assert_allclose(symmetric_matvec(A, False)(x), A @ x, rtol=1e-12)
    X = np.random.default_rng(3).normal(size=(60, 2))  # a narrow block: SciPy's products
    np.testing.assert_allclose(symmetric_matvec(sp.triu(A).tocsr(), True)(X), A @ X, rtol=1e-12)
    monkeypatch.setattr(krylov, "_upper_kernel", lambda: None)  # without Numba
    np.testing.assert_allclose(symmetric_matvec(sp.triu(A).tocsr(), True)(x), A @ x, rtol=1e-12)


def test_a_block_of_columns_is_the_whole_product_in_any_layout():
    A = _spd(60)
    X = np.random.default_rng(2).normal(size=(60, BLOCK + 3))
    for K, upper in ((sp.triu(A).tocsr(), True), (A, False)):
        product = symmetric_matvec(K, upper)
        np.testing.assert_allclose(product(X), A @ X, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(product(np.asfortranarray(X)), A @ X, rtol=1e-12, atol=1e-12)


def test_pcg_meets_its_tolerance_with_an_earlier_matrix_as_preconditioner():
    A = _spd(80)
    nearby = A + sp.diags(np.linspace(0.0, 0.05, 80))  # an "earlier tangent"
    precondition = lambda b: np.linalg.solve(nearby.toarray(), b)  # noqa: E731
    b = np.random.default_rng(2).normal(size=80)
    out = pcg(A.__matmul__, precondition, b, 1e-10, 50)
    assert out.reason == ""
    exact = np.linalg.solve(A.toarray(), b)
    np.testing.assert_allclose(out.x, exact, rtol=1e-7, atol=1e-9 * np.abs(exact).max())
    assert np.linalg.norm(b - A @ out.x) <= 1e-10 * np.linalg.norm(b)
    assert out.iterations < 20  # a good preconditioner: far fewer than n iterations
    # with the exact inverse it is done at once
    exact_inverse = lambda b: np.linalg.solve(A.toarray(), b)  # noqa: E731
    assert pcg(A.__matmul__, exact_inverse, b, 1e-10, 50).iterations == 1


def test_pcg_names_an_indefinite_matrix_and_a_slow_one():
    A = sp.diags([1.0, 2.0, -3.0, 4.0]).tocsr()
    out = pcg(A.__matmul__, lambda b: b, np.ones(4), 1e-10, 20)
    assert out.x is None and "non-positive curvature" in out.reason
    slow = pcg(_spd(80).__matmul__, lambda b: b, np.ones(80), 1e-14, 3)
    assert slow.x is None and slow.reason == "no convergence in 3 iterations"
    assert pcg(A.__matmul__, lambda b: b, np.zeros(4), 1e-10, 5).x == pytest.approx(np.zeros(4))
