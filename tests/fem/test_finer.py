"""A press on a subdivided part is solved on the part it came from and answered on its
vertices: the same solve, every vertex a node, the contact force kept.
"""

import numpy as np
import pytest

from fem.contact import press, skin_weights
from fem.finer import FinerPart, meshed
from fem.shapes import Sphere, skin_near, touching
from fem.simulate import press_solver, tissue_mesh
from fem.solver import Solver
from stmpl.body import tube

QUADRATIC = {"subdivisions": 1, "layers": 2, "order": 2}


def _ball(coarse):
    """``(ball, direction, where)``: a 6 mm ball touching a tube's skin at its middle."""
    at = int(np.argmin(np.linalg.norm(coarse.vertices - [0.03, 0, 0.04], axis=1)))
    p, n = coarse.vertices[at], coarse.normals[at]
    return touching(Sphere(p + 0.006 * n, 0.006), -n, skin_near(coarse, p, 0.018)), -n, p


@pytest.fixture(scope="module")
def pressed():
    """The ball pressed 2 mm into a tube of gel subdivided once, and its solver."""
    coarse = tube(0.03, 0.08, 12, 9)
    fine = coarse.subdivided(1)
    ball, direction, p = _ball(coarse)
    solver = press_solver(fine, np.full(fine.n_vertices, 0.008), QUADRATIC, "paper", None, p[None])
    (answer,) = press(solver, ball, direction, [0.002])
    assert answer.ok, answer.reason
    return fine, solver, answer


def test_a_subdivided_part_is_meshed_on_the_part_it_came_from(pressed):
    fine, solver, answer = pressed
    assert solver.mesh.part is fine.coarser
    assert answer.displacement.shape == (fine.n_vertices, 3)
    # every vertex of the finer part is a node of the mesh: its own rest position
    nodes = solver.answers.nodes
    x = np.concatenate([solver.mesh.nodes, solver.mesh.nodes[solver.edges].mean(1)])
    np.testing.assert_allclose(x[nodes], fine.vertices, atol=1e-12)
    # the ball's depth is met at the vertex it presses
    assert np.abs(answer.displacement).max() == pytest.approx(0.002, rel=0.02)


def test_the_coarser_mesh_answers_as_the_finer_part_s_own(pressed):
    """Refined one level more near the ball, the coarser part's mesh is the finer part's
    there: the reaction and the dent agree, with a third fewer unknowns.
    """
    fine, solver, answer = pressed
    ball, direction, p = _ball(fine.coarser)
    mesh = tissue_mesh(fine, np.full(fine.n_vertices, 0.008), QUADRATIC, near=p[None])[0]
    own = Solver(mesh, order=2)
    assert solver.n_all < 0.8 * own.n_all
    (same,) = press(own, ball, direction, [0.002])
    assert same.ok, same.reason
    assert answer.reaction == pytest.approx(same.reaction, rel=1e-4)
    peak = np.linalg.norm(same.displacement, axis=1).max()
    assert np.abs(answer.displacement - same.displacement).max() < 1e-3 * peak


def test_the_answer_on_the_finer_part_is_the_coarser_part_s_where_they_share_vertices(pressed):
    fine, solver, answer = pressed
    coarse = FinerPart(solver, fine.coarser)
    n = fine.coarser.n_vertices
    np.testing.assert_array_equal(answer.displacement[:n], coarse.displacement(answer.state))
    # the contact force kept on either: the pressure over the vertices' areas sums to it
    nodes, weights = skin_weights(solver)
    nodal = np.zeros(solver.n_all)
    nodal[nodes] = weights * answer.multipliers
    on_coarse = (coarse.pressure(nodal) * fine.coarser.vertex_areas).sum()
    assert on_coarse == pytest.approx(answer.total, rel=1e-9)
    np.testing.assert_allclose(answer.pressure, solver.answers.pressure(nodal))
    assert (answer.pressure * fine.vertex_areas).sum() == pytest.approx(answer.total, rel=1e-9)
    assert (answer.push * fine.vertex_areas).sum() == pytest.approx(answer.reaction, rel=1e-9)
    assert answer.total > 0


def test_a_thickness_of_its_own_or_linear_elements_mesh_the_finer_part_itself():
    coarse = tube(0.03, 0.08, 12, 9)
    fine = coarse.subdivided(1)
    t = np.full(fine.n_vertices, 0.008)
    part, thickness = meshed(fine, t, 2)
    assert part is coarse and thickness.shape == (coarse.n_vertices,)
    bumpy = t.copy()
    bumpy[coarse.n_vertices] += 0.001  # a midpoint thicker than its edge's ends
    assert meshed(fine, bumpy, 2)[0] is fine
    assert meshed(fine, t, 1)[0] is fine
    assert meshed(coarse, t[: coarse.n_vertices], 2)[0] is coarse
    assert meshed(fine.with_vertices(fine.vertices * 1.01), t, 2)[0].n_vertices == fine.n_vertices


def test_a_part_whose_vertices_are_not_nodes_is_refused():
    """Linear elements have no node at an edge's midpoint."""
    coarse = tube(0.03, 0.08, 12, 9)
    flat = {"subdivisions": 0, "layers": 2, "order": 1}
    mesh = tissue_mesh(coarse, np.full(coarse.n_vertices, 0.008), flat)[0]
    solver = Solver(mesh, order=1, answer_on=coarse.subdivided(1))
    with pytest.raises(ValueError, match="mm from the mesh's nearest skin node"):
        solver.answers
