"""The compliance operator is the linear FEM: superposition of its columns reproduces a direct
solve, and it is the tangent of the Neo-Hookean solve at rest."""

import numpy as np
import pytest

from fem.compliance import compliance, sparsify
from fem.material import LinearElastic, NeoHookean
from fem.mesh import shell_mesh
from fem.solver import Solver
from stmpl.body.primitives import tube

RES = {"subdivisions": 1, "layers": 1, "order": 1, "refine_radius": None}


@pytest.fixture(scope="module")
def part():
    return tube(radius=0.04, length=0.2, n_around=12, n_along=8)


@pytest.fixture(scope="module")
def G(part):
    return compliance(part, 0.008, RES, NeoHookean(), block=40)


def _load(part, rng):
    f = np.zeros(part.n_vertices)
    f[rng.choice(part.n_vertices, 5, replace=False)] = rng.uniform(0.01, 0.03, 5)
    return f


def test_superposition_equals_a_direct_linear_solve(part, G, rng):
    f = _load(part, rng)
    mesh = shell_mesh(part, np.full(part.n_vertices, 0.008), layers=1, subdivisions=1)
    sol = Solver(mesh, LinearElastic(), order=1).solve(f)
    assert sol.ok
    u = sol.part_displacement(mesh)
    assert np.abs(u).max() > 1e-4                   # tenths of a mm: a real response
    np.testing.assert_allclose(np.einsum("ijc,j->ic", G, f), u, atol=1e-6 * np.abs(u).max())


def test_it_is_the_neo_hookean_tangent_at_rest(part, G, rng):
    f = _load(part, rng) * 0.01                     # a light touch: within 0.1 % of linear
    mesh = shell_mesh(part, np.full(part.n_vertices, 0.008), layers=1, subdivisions=1)
    sol = Solver(mesh, NeoHookean(), order=1).solve(f)
    u = sol.part_displacement(mesh)
    err = np.abs(np.einsum("ijc,j->ic", G, f) - u).max() / np.abs(u).max()
    assert err < 1e-3


def test_reciprocity_and_blocks(part, G):
    """Maxwell-Betti: the normal response at i to a normal push at j equals that at j to i
    (the traction spreading is symmetric on a uniform tube), the fixed rims do not move, and the
    block size does not change the operator."""
    Gn = -np.einsum("ijc,ic->ij", G, part.normals)  # inward normal response, m/N
    z = part.vertices[:, 2]
    rim = np.isclose(z, z.min()) | np.isclose(z, z.max())
    assert rim.sum() == 24 and np.abs(G[rim]).max() == 0
    interior = np.abs(z - z.mean()) < 0.05
    assert Gn.diagonal()[interior].min() > 0
    sub = Gn[np.ix_(interior, interior)]
    assert np.abs(sub - sub.T).max() < 0.05 * sub.max()
    G2 = compliance(part, 0.008, RES, NeoHookean(), block=7)
    np.testing.assert_allclose(G2, G, atol=1e-12)


def test_sparsify_keeps_what_counts(G):
    stack = np.stack([G, 2 * G])
    index, values, dropped = sparsify(stack, tol=1e-2)
    assert dropped <= 1e-2 and values.shape == (2, index.shape[1], 3)
    dense = np.zeros_like(stack)
    dense[:, index[0], index[1]] = values
    err = np.linalg.norm(dense - stack, axis=-1).max() / np.linalg.norm(stack, axis=-1).max()
    assert err <= 1e-2 and index.shape[1] < G.shape[0] ** 2
