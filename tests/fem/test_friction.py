"""Coulomb's friction between an object and the skin: the potential's derivatives, a punch
dragged across a slab that sticks and then slides at Coulomb's bound, and bad coefficients.
"""

from dataclasses import replace

import numpy as np
import pytest
import trimesh

from fem.contact import Contact, slide
from fem.friction import REACHED, SKIN_FRICTION, Friction, coefficient, motion
from fem.shapes import Punch, Surface
from fem.verification import punch_slab


@pytest.fixture(scope="module")
def slab():
    return punch_slab(1.0, spacing=0.25)


def test_the_friction_potential_s_gradient_and_hessian_are_its_derivatives(slab):
    """Finite differences of the energy give the gradient, and of the gradient the Hessian,
    for nodes sticking (slip below eps) and sliding alike.
    """
    solver, a, h = slab
    punch = Punch([0, 0, 0], [0, 0, -1], a)
    contact = Contact(solver, punch, 1e6)
    rng = np.random.default_rng(0)
    on = rng.random(len(contact.nodes)) < 0.5
    contact.multipliers = np.where(on, rng.uniform(50, 200, len(on)), 0.0)
    contact._normals = np.tile([0.0, 0.0, 1.0], (len(on), 1))
    friction = Friction(contact, 0.7, slip=1e-5)
    u0 = 1e-5 * rng.standard_normal((solver.n_all, 3))
    friction.begin(u0, np.tile([2e-5, 0.0, 0.0], (len(on), 1)))
    friction.relag()
    for size in (3e-6, 1e-4):  # most nodes sticking, then sliding
        u = u0 + size * rng.standard_normal(u0.shape)
        du = 1e-9 * rng.standard_normal(u0.shape)
        g = friction.gradient(u)
        de = friction.energy(u + du) - friction.energy(u - du)
        assert de == pytest.approx(2 * np.vdot(g, du), rel=1e-5)
        rows, cols, vals = friction.hessian(u)
        n = 3 * solver.n_all
        H = np.zeros((n, n))
        np.add.at(H, (rows, cols), vals)
        dg = (friction.gradient(u + du) - friction.gradient(u - du)).reshape(-1)
        np.testing.assert_allclose(dg, 2 * H @ du.reshape(-1), rtol=1e-4, atol=1e-12)
        assert np.linalg.eigvalsh(H[np.ix_(rows[::9] // 3 * 3, rows[::9] // 3 * 3)]).min() > -1e-9


def test_a_dragged_punch_sticks_then_slides_at_coulomb_s_bound(slab):
    """A flat punch pressed 1 % of the slab's thickness, then drawn across it: dragged 0.1 mm,
    the skin under it moves with it (it sticks) and the pull stays below Coulomb's bound;
    dragged 1 mm it slides, and the pull is mu times the normal force (within 0.1 %).
    Frictionless, the skin stays where the press left it and nothing pulls.
    """
    solver, a, h = slab
    punch = Punch([0, 0, 0], [0, 0, -1], a)
    v = solver.mesh.part.vertices
    under = np.flatnonzero((np.linalg.norm(v, axis=1) < 0.9 * a) & (v[:, 0] > 1e-9))
    for mu in (0.0, SKIN_FRICTION):
        pressed, stuck, slid = slide(
            solver, punch, [0, 0, -1], 0.01 * h, [1, 0, 0], [1e-4, 1e-3], mu
        )
        assert pressed.ok and stuck.ok and slid.ok
        followed = stuck.displacement[under, 0] - pressed.displacement[under, 0]
        if mu == 0:
            assert np.abs(followed).max() < 2e-6 and np.abs(slid.friction).max() == 0
            assert abs(slid.reaction) < 0.01 * slid.total  # the rounded rim's own slope
            continue
        assert followed.mean() > 0.8 * 1e-4
        assert 0 < -stuck.friction[0] < mu * stuck.total
        assert -slid.friction[0] == pytest.approx(mu * slid.total, rel=1e-3)
        assert slid.reaction == pytest.approx(mu * slid.total, rel=0.01)


def test_a_closing_mesh_moves_each_point_by_its_path():
    """A mesh closing along its path moves a point on a face by the path interpolated there."""
    tri = Surface(
        np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]]),
        np.array([[0, 1, 2]]),
        path=np.array([[1.0, 0, 0], [0, 1, 0], [0, 0, 1]]),
    )
    x = np.array([[0.25, 0.25, 0.001], [0.0, 0.0, 0.0]])
    np.testing.assert_allclose(motion(tri, None, x, 2.0), [[1.0, 0.5, 0.5], [2.0, 0, 0]])
    np.testing.assert_allclose(motion(tri, [0, 0, 1.0], x, 2.0), [[0, 0, 2.0]] * 2)
    with pytest.raises(ValueError, match="has no path"):  # a mesh that does not close
        motion(replace(tri, path=None), None, x, 2.0)


def test_a_closing_mesh_s_motion_is_exact_wherever_a_step_can_press():
    """Within :data:`REACHED` of the mesh a point moves by the path at its nearest point, as
    found by searching every triangle; farther out by the path at a point of the mesh.
    """
    ball = trimesh.creation.icosphere(3, radius=0.02)
    path = ball.vertices * [30.0, 60.0, 90.0]  # m per m of depth, smooth over the mesh
    mesh = Surface(np.asarray(ball.vertices), np.asarray(ball.faces), path=path)
    rng = np.random.default_rng(0)
    out = rng.normal(size=(400, 3))
    out /= np.linalg.norm(out, axis=1)[:, None]
    x = out * rng.uniform(0.0195, 0.06, 400)[:, None]
    near = np.abs(np.linalg.norm(x, axis=1) - 0.02) < REACHED - 1e-4
    got, exact = motion(mesh, None, x, 1e-4), 1e-4 * mesh.path_at(x)
    np.testing.assert_array_equal(got[near], exact[near])
    reach = 1e-4 * np.linalg.norm(path, axis=1).max()
    assert np.all(np.linalg.norm(got, axis=1) <= reach * (1 + 1e-12))
    # a long step widens the band: every point within it is exact
    np.testing.assert_array_equal(motion(mesh, None, x, 0.05), 0.05 * mesh.path_at(x))


@pytest.mark.parametrize("bad", [-0.1, float("nan"), float("inf"), "0.5", True, None])
def test_a_bad_friction_coefficient_is_refused_by_name(bad):
    with pytest.raises(ValueError, match="friction coefficient"):
        coefficient(bad)
