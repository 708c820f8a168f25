"""The deformation gradient and the inverse of F: compiled and NumPy alike, exact on a
homogeneous deformation.
"""

import numpy as np
import pytest

from fem.kinematics import _kernels, deformation_gradient, det3, inv3
from fem.mesh import shell_mesh
from fem.solver import Solver
from stmpl.body.primitives import tube


@pytest.mark.parametrize("order", [1, 2])
@pytest.mark.parametrize("compiled", [True, False])
def test_a_homogeneous_deformation_has_its_own_gradient_everywhere(order, compiled):
    part = tube(radius=0.04, length=0.08, n_around=10, n_along=4)
    S = Solver(shell_mesh(part, np.full(part.n_vertices, 0.008), layers=1), order=order)
    X = S.mesh.nodes
    if order == 2:  # the edge nodes at the edges' middles
        X = np.concatenate([X, X[S.edges].mean(1)])
    A = np.array([[0.1, -0.05, 0.02], [0.03, -0.2, 0.04], [0.0, 0.07, 0.15]])
    F = deformation_gradient(X @ A.T, S.conn, S.G, compiled=compiled)
    assert F.shape == (*S.W.shape, 3, 3)
    np.testing.assert_allclose(F, np.broadcast_to(np.eye(3) + A, F.shape), atol=1e-12)
    Finv, J = inv3(F.reshape(-1, 3, 3), compiled=compiled)
    np.testing.assert_allclose(J, np.linalg.det(np.eye(3) + A), rtol=1e-13)
    np.testing.assert_allclose(Finv, np.broadcast_to(np.linalg.inv(np.eye(3) + A), Finv.shape))


def test_the_compiled_kinematics_are_numpy_s_to_rounding():
    if _kernels() is None:
        pytest.skip("Numba is not installed: NumPy's way is the only one")
    rng = np.random.default_rng(3)
    conn = rng.integers(0, 50, (40, 10))
    G = rng.normal(size=(40, 4, 10, 3)) * 100.0
    u = rng.normal(size=(50, 3)) * 1e-3
    F = deformation_gradient(u, conn, G)
    np.testing.assert_allclose(F, deformation_gradient(u, conn, G, compiled=False), atol=1e-15)
    Ff = F.reshape(-1, 3, 3)
    (a, Ja), (b, Jb) = inv3(Ff), inv3(Ff, compiled=False)
    np.testing.assert_array_equal(Ja, Jb)  # the same cofactors in the same order
    np.testing.assert_array_equal(a, b)
    np.testing.assert_allclose(Ja, det3(Ff), rtol=1e-14)
    # a flat element's F gives an infinite inverse, as NumPy's division does, not an error
    flat = np.zeros((1, 3, 3))
    with np.errstate(divide="ignore", invalid="ignore"):
        inverse, J = inv3(flat)
    assert J[0] == 0.0 and not np.isfinite(inverse).any()
