"""The local FEM: the patch a load moves, its cut, the growth rule, and its answer against the
whole part's solve.
"""

import numpy as np
import pytest

from fem import local
from fem.force_control import press_to_force
from fem.material import NeoHookean
from fem.shapes import Punch
from fem.simulate import simulate, tissue_mesh
from fem.solver import Solver
from stmpl import loads, reach
from stmpl.body.primitives import tube

RES = {"subdivisions": 1, "layers": 2, "refine_radius": 0.03, "order": 1}
RES_P2 = {"subdivisions": 0, "layers": 1, "refine_radius": None, "order": 2}


@pytest.fixture(scope="module")
def long_tube():
    return tube(radius=0.04, length=0.4, n_around=24, n_along=30)


def test_a_patch_is_the_loaded_neighbourhood_with_its_cut_held(long_tube):
    part = long_tube
    ld = loads.disk(part, uv=(0.5, 0.5), radius=0.02, total=0.2)
    p = local.patch(part, ld.force, 0.05)
    assert not p.whole and set(ld.vertices) <= set(p.vertices)
    dist = np.linalg.norm(
        part.vertices[p.vertices][:, None] - part.vertices[ld.vertices][None], axis=2
    ).min(1)
    assert dist.max() <= 0.05 + 1e-12
    assert len(p.part.rims) == 1 and len(p.ring) > 0  # a disk's patch: one cut
    assert not np.isin(p.ring, np.concatenate(p.part.rims)).any()
    np.testing.assert_array_equal(p.part.normals, part.normals[p.vertices])
    u = np.ones((p.part.n_vertices, 3))
    assert p.lift(u, part.n_vertices)[p.vertices].sum() == 3 * len(p.vertices)
    assert local.patch(part, ld.force, 1.0).whole
    with pytest.raises(ValueError, match="no loaded vertex"):
        local.patch(part, np.zeros(part.n_vertices), 0.05)


def test_a_patch_reaching_the_parts_own_rim_is_cut_only_where_it_was_cut(long_tube):
    """A band near the end of the tube: the patch meets the tube's own (held) rim; the ring
    that is checked lies along the new cut only.
    """
    part = long_tube
    ld = loads.band(part, at=0.05, width=0.02, total=0.2)
    p = local.patch(part, ld.force, 0.04)
    own = np.concatenate(part.rims)
    assert np.isin(p.vertices, own).any()
    near_own = np.isin(p.vertices[p.ring], own)
    assert not near_own.any()


def test_local_matches_the_whole_solve_and_grows_when_too_tight(long_tube):
    part = long_tube
    t = np.full(part.n_vertices, 0.0075)
    ld = loads.disk(part, uv=(0.5, 0.5), radius=0.02, total=1.0)
    mesh, sols = simulate(part, t, ld.force, [0.1, 0.2], RES)
    whole = sols[-1].part_displacement(mesh)
    peak = np.linalg.norm(whole, axis=1).max()
    m2, s2, res = local.simulate_local(part, t, ld.force, [0.1, 0.2], RES)
    assert all(s.ok for s in s2) and not res.patch.whole
    u = res.patch.lift(s2[-1].part_displacement(m2), part.n_vertices)
    assert np.linalg.norm(u - whole, axis=1).max() < 0.01 * peak
    assert res.attempts[-1]["ring_moved"] <= reach.RING_TOLERANCE
    assert res.patch.part.n_vertices < 0.6 * part.n_vertices
    # a first cut far too tight is grown until the ring stays still
    m3, s3, tight = local.simulate_local(part, t, ld.force, [0.2], RES, margin=0.012)
    assert len(tight.attempts) > 1 and tight.attempts[0]["ring_moved"] > reach.RING_TOLERANCE
    assert [a["margin_m"] for a in tight.attempts] == pytest.approx(
        [0.012 * reach.GROW**k for k in range(len(tight.attempts))]
    )
    u3 = tight.patch.lift(s3[-1].part_displacement(m3), part.n_vertices)
    assert np.linalg.norm(u3 - whole, axis=1).max() < 0.01 * peak


def test_the_fem_predictor_takes_fidelity(long_tube):
    from stmpl import predictor
    from stmpl.scene import Scene

    part = long_tube
    scene = Scene.from_load(
        part,
        np.full(part.n_vertices, 0.0075),
        loads.disk(part, uv=(0.5, 0.5), radius=0.02, total=0.2),
    )
    full = predictor.create("fem", res=RES).predict(scene)
    auto = predictor.create("fem", res=RES, fidelity="auto").predict(scene)
    assert full.info["local"] is None and auto.info["local"]["vertices"] < part.n_vertices
    peak = full.magnitude.max()
    assert np.abs(auto.displacement - full.displacement).max() < 0.01 * peak
    with pytest.raises(ValueError, match="fidelity must be one of"):
        predictor.create("fem", fidelity="half")


def test_a_load_the_tissue_cannot_carry_fails_after_one_growth_not_the_whole_part(long_tube):
    """When nothing converges the patch grows once (the cut might be to blame); a second failure
    is the load's own and is returned as failed, not solved again on ever larger patches.
    """
    part = long_tube
    t = np.full(part.n_vertices, 0.0075)
    ld = loads.disk(part, uv=(0.5, 0.5), radius=0.02, total=1.0)
    from fem.solver import SolverOptions

    opts = SolverOptions(max_iter=1, max_substeps=0)  # no solve can converge
    mesh, sols, res = local.simulate_local(part, t, ld.force, [0.1, 0.2], RES, options=opts)
    assert not any(s.ok for s in sols)
    assert len(res.attempts) == local.FAILED_ATTEMPTS == 2 and not res.patch.whole
    assert res.attempts[1]["margin_m"] == pytest.approx(reach.GROW * res.attempts[0]["margin_m"])


def _press_both(part, tissue, force, radius, res, order):
    """A disk pushed into ``part`` until it carries ``force``: the patch's answer and the
    whole part's.
    """
    t = np.full(part.n_vertices, 0.0075)
    top = int(np.argmin(np.abs(part.vertices[:, 2] - 0.2) + 10 * (1 - part.normals[:, 0])))
    p, n = part.vertices[top], part.normals[top]
    shape = Punch(p, -n, radius)
    answer, result = local.press_local(part, t, shape, -n, force, res, tissue)
    mesh, material = tissue_mesh(part, t, res, tissue, near=p[None])
    solver = Solver(mesh, material or NeoHookean(), order=order)
    return answer, result, press_to_force(solver, shape, -n, force), p


@pytest.mark.parametrize(
    "tissue, force, res, order, share",
    [
        ("paper", 0.1, RES, 1, 0.6),
        pytest.param("forearm", 1.0, RES_P2, 2, 0.75, marks=pytest.mark.slow),
    ],
)
def test_a_pressed_object_solved_on_its_patch_matches_the_whole_part(
    long_tube, tissue, force, res, order, share
):
    """A 20 mm disk pushed until it carries a force, on the paper's gel (fast) and the forearm
    preset (slow, 1 N): the patch's answer lies within 1 % (of the deepest displacement) of
    the whole tube's, carries the force within 1 %, and its pressure sits under the disk.
    On the gel the patch is under 0.6 of the tube; the forearm's stiff skin spreads the dent
    along it, and the patch reaches 0.7 of it (504 of 720 vertices).
    """
    answer, result, whole, p = _press_both(long_tube, tissue, force, 0.02, res, order)
    assert answer.ok and whole.ok, (answer.reason, whole.reason)
    assert not result.patch.whole
    assert result.patch.part.n_vertices < share * long_tube.n_vertices
    assert answer.reaction == pytest.approx(force, rel=0.01)
    peak = np.linalg.norm(whole.displacement, axis=1).max()
    assert np.linalg.norm(answer.displacement - whole.displacement, axis=1).max() < 0.01 * peak
    pressed = answer.pressure > 0
    assert np.linalg.norm(long_tube.vertices[pressed] - p, axis=1).max() < 0.02 + 0.015
    # the refined skin's contact forces all reach the part's vertices
    carried = float(np.sum(whole.pressure * long_tube.vertex_areas))
    assert carried == pytest.approx(whole.total, rel=1e-9)
