"""The linear solvers: PARDISO's single-precision factorisation answers as the double one does
(refined), says when a tangent is indefinite, and gives way to double precision where single
cannot reach the answer.
"""

import numpy as np
import pytest
import scipy.sparse as sp

from fem.contact import press
from fem.linear_solvers import IndefiniteTangent, available_linear_solvers, make_linear_solver
from fem.options import SolverOptions
from fem.shapes import Sphere, skin_near, touching
from fem.simulate import tissue_mesh
from fem.solver import Solver
from stmpl.body import tube

pytestmark = pytest.mark.skipif(
    "pardiso" not in available_linear_solvers(), reason="PARDISO (MKL) is not installed"
)


def _upper(K: sp.spmatrix) -> sp.csr_matrix:
    return sp.triu(K).tocsr()


def _laplacian(n: int, shift: float) -> sp.csr_matrix:
    """A 2D grid Laplacian of ``n x n`` points plus ``shift`` times the identity (SPD)."""
    d = sp.diags([-1.0, 2.0, -1.0], [-1, 0, 1], shape=(n, n))
    eye = sp.identity(n)
    return (sp.kron(d, eye) + sp.kron(eye, d) + shift * sp.identity(n * n)).tocsr()


def test_single_precision_solves_as_double_once_refined():
    K = _laplacian(40, 1e-3)
    rng = np.random.default_rng(0)
    b = rng.normal(size=(K.shape[0], 2))
    double, single = make_linear_solver("pardiso"), make_linear_solver("pardiso_single")
    for s in (double, single):
        s.factor(_upper(K))
    x, y = double.solve(b), single.solve(b)
    assert single._single  # the single factorisation answered, refined
    assert np.linalg.norm(K @ y - b) <= 1e-9 * np.linalg.norm(b)
    np.testing.assert_allclose(y, x, rtol=0, atol=1e-8 * np.abs(x).max())
    np.testing.assert_allclose(single.solve(b[:, 0]), x[:, 0], atol=1e-8 * np.abs(x).max())
    # unrefined, as a preconditioner: a few digits
    rough = single.precondition(b)
    assert 1e-12 < np.linalg.norm(K @ rough - b) / np.linalg.norm(b) < 1e-2


def test_an_indefinite_matrix_is_said_to_be_so():
    K = _laplacian(10, -1.0)  # eigenvalues down to about -1
    with pytest.raises(IndefiniteTangent):
        make_linear_solver("pardiso_single").factor(_upper(K))


def test_a_matrix_too_ill_conditioned_for_single_precision_is_solved_in_double():
    """A chain of springs held only by a spring 1e-9 as stiff: singular in single precision."""
    n = 400
    d = np.full(n, 2.0)
    d[[0, -1]] = 1.0
    off = np.full(n - 1, -1.0)
    K = (sp.diags(d + 1e-9) + sp.diags(off, 1) + sp.diags(off, -1)).tocsr()
    b = np.random.default_rng(1).normal(size=n)
    single = make_linear_solver("pardiso_single")
    single.factor(_upper(K))
    y = single.solve(b)
    assert not single._single  # it gave way to double precision
    assert np.linalg.norm(K @ y - b) <= 1e-6 * np.linalg.norm(b)


def test_a_press_meets_the_same_equilibrium_in_single_precision():
    part = tube(0.03, 0.08, 12, 9)
    at = int(np.argmin(np.linalg.norm(part.vertices - [0.03, 0, 0.04], axis=1)))
    p, n = part.vertices[at], part.normals[at]
    ball = touching(Sphere(p + 0.006 * n, 0.006), -n, skin_near(part, p, 0.018))
    res = {"subdivisions": 1, "layers": 2, "order": 2}
    mesh = tissue_mesh(part, np.full(part.n_vertices, 0.008), res, near=p[None])[0]
    answers = []
    for name in ("pardiso", "pardiso_single"):
        solver = Solver(mesh, options=SolverOptions(linear_solver=name), order=2)
        (a,) = press(solver, ball, -n, [0.002])
        assert a.ok, a.reason
        answers.append(a)
    assert answers[1].reaction == pytest.approx(answers[0].reaction, rel=1e-6)
    peak = np.abs(answers[0].displacement).max()
    np.testing.assert_allclose(answers[1].displacement, answers[0].displacement, atol=1e-6 * peak)
