"""Objects closing on the skin with friction, answered by a linear compliance (fem/closure.py):
against Coulomb's law where it has a closed form (one vertex of an isotropic compliance), and
its conditions on a coupled patch.
"""

import numpy as np
import pytest

from fem.closure import CONTACT_RULES, HeldColumns, closure_forces, contact_forces

G1 = 1e-3  # m/N: one vertex's isotropic compliance
Z = np.array([[0.0, 0.0, 1.0]])  # its outward normal


def _one(way, gap=-0.002, friction=0.5, rounding=0.0005):
    f = closure_forces(G1 * np.eye(3), Z, np.array([gap]), np.array([way]), friction, 20, rounding)
    return G1 * f[0]  # the vertex's displacement, m


def test_a_press_along_the_normal_moves_the_skin_to_the_rounded_surface():
    """Pressed straight in 2 mm past the object's faces, the skin lies on its rounded surface:
    2.5 mm in, nothing along it, whatever the friction.
    """
    for friction in (0.0, 0.5, np.inf):
        np.testing.assert_allclose(_one([0.0, 0.0, -1.0], friction=friction), [0, 0, -0.0025])


@pytest.mark.parametrize("sweep", [0.3, 0.8])
def test_a_sweeping_object_drags_the_skin_as_far_as_coulomb_lets_it(sweep):
    """The object moves ``sweep`` m along the skin per m into it. The skin sticks while the
    drag's ratio to the push stays within the friction coefficient 0.5: it moves with the
    object; beyond, it slips, and (one isotropic compliance) its tangential motion is 0.5 times
    its normal one.
    """
    u = _one([sweep, 0.0, -1.0])
    assert u[2] == pytest.approx(-0.0025)
    assert u[0] == pytest.approx(min(sweep, 0.5) * 0.0025)
    assert u[1] == pytest.approx(0.0, abs=1e-15)


def test_no_friction_no_drag_and_stuck_skin_goes_all_the_way():
    assert _one([0.8, 0.0, -1.0], friction=0.0)[0] == pytest.approx(0.0, abs=1e-15)
    np.testing.assert_allclose(_one([0.8, 0.0, -1.0], friction=np.inf), [0.002, 0, -0.0025])


def test_an_object_that_does_not_reach_the_skin_moves_nothing():
    assert not _one([0.0, 0.0, -1.0], gap=0.001).any()


def _patch(k=12, seed=0):
    """A coupled compliance among ``k`` vertices of a flat skin (z up): SPD, its diagonal
    dominant, neighbours pulled along with one another.
    """
    rng = np.random.default_rng(seed)
    x = np.column_stack([rng.uniform(-0.02, 0.02, (k, 2)), np.zeros(k)])
    d = np.linalg.norm(x[:, None] - x[None], axis=-1)
    C = np.exp(-d / 0.01)  # positive definite (an exponential kernel)
    G = 1e-3 * np.kron(C, np.eye(3))
    return x, G


def test_on_a_coupled_patch_every_force_pushes_and_the_touched_skin_meets_the_object():
    """A ball's worth of gap (deepest in the middle) closing straight in, with friction: every
    contact force pushes into the skin, within Coulomb's cone; each vertex the object still
    pushes lies on the object's rounded surface; the others were let go (or never reached) and
    lie clear of it (below its surface, not inside the object).
    """
    x, G = _patch()
    k = len(x)
    n = np.tile([0.0, 0.0, 1.0], (k, 1))
    gap = 0.002 * (np.linalg.norm(x[:, :2], axis=1) / 0.02) ** 2 - 0.0015
    way = np.tile([0.2, 0.0, -1.0], (k, 1))
    f = closure_forces(G, n, gap, way, 0.5, 20, 0.0005)
    u = (G @ f.ravel()).reshape(k, 3)
    fn = (f * n).sum(1)
    pushed = fn < 0
    assert pushed.sum() >= 2
    assert np.all(fn[~pushed] == 0) and not f[~pushed].any()
    ft = np.linalg.norm(f - fn[:, None] * n, axis=1)
    assert np.all(ft <= 0.5 * -fn * (1 + 1e-6))
    np.testing.assert_allclose(u[pushed, 2], gap[pushed] - 0.0005, atol=1e-9)
    assert np.all(u[~pushed, 2] <= gap[~pushed] - 0.0005 + 1e-9)


@pytest.mark.parametrize(
    "change, words",
    [
        ({"gap": np.array([np.nan])}, "gap is not finite"),
        ({"way": np.zeros((2, 3))}, "for k = 1"),
        ({"friction": -0.1}, "friction must be >= 0"),
        ({"steps": 0}, "steps must be a whole number"),
        ({"rounding": -1e-3}, "rounding must be a length"),
        ({"rule": "sometimes"}, "rule must be one of"),
    ],
)
def test_bad_input_is_refused_by_name(change, words):
    args = {
        "G": G1 * np.eye(3),
        "normals": Z,
        "gap": np.array([-0.001]),
        "way": np.array([[0.0, 0.0, -1.0]]),
        **change,
    }
    with pytest.raises(ValueError, match=words):
        closure_forces(**args)


def test_the_held_block_read_column_by_column_answers_as_the_whole_block():
    """The held vertices' compliance read from a larger skin's as the contact reaches them
    (:class:`HeldColumns`, NumPy's steps) gives the forces the whole block does, reading only
    the columns of the vertices the objects touch; a column that is not finite is refused by
    name.
    """
    x, G = _patch(k=30, seed=1)
    held = np.arange(3, 25)  # the vertices near the objects, in a larger skin
    at = (held[:, None] * 3 + np.arange(3)).ravel()
    n = np.tile([0.0, 0.0, 1.0], (len(held), 1))
    r = np.linalg.norm(x[held, :2], axis=1)
    gap = 0.002 * (r / 0.02) ** 2 - 0.0008  # a shallow ball: the middle few vertices touched
    way = np.tile([0.2, 0.0, -1.0], (len(held), 1))
    G = np.asfortranarray(G.astype(np.float32))  # kept as the skin's compliance is
    whole = closure_forces(G[np.ix_(at, at)], n, gap, way, 0.5, 20, 0.0005, compiled=False)
    block = HeldColumns(G, at)
    read = closure_forces(block, n, gap, way, 0.5, 20, 0.0005, compiled=False)
    np.testing.assert_allclose(read, whole, rtol=0, atol=1e-12 * np.abs(whole).max())
    touched = np.flatnonzero(whole.any(1))
    assert 0 < len(touched) < len(held) // 2
    assert block._have.sum() < 3 * len(held) // 2  # not every column was read
    assert block._have[(touched[:, None] * 3 + np.arange(3)).ravel()].all()
    bad = G.copy(order="F")
    bad[:, at[3 * touched[0]]] = np.nan
    with pytest.raises(ValueError, match="G is not finite"):
        closure_forces(HeldColumns(bad, at), n, gap, way, 0.5, 20, 0.0005, compiled=False)


@pytest.mark.parametrize("rule", CONTACT_RULES)
@pytest.mark.parametrize("friction", [0.0, 0.5, np.inf])
def test_the_compiled_closure_answers_as_the_numpy_one(friction, rule):
    """The closing's steps compiled (Numba) give NumPy's forces within rounding, on a coupled
    patch pressed and swept so that vertices stick, slip and are let go; a compliance that is
    not finite where the contact reads it is refused by name.
    """
    x, G = _patch(k=40, seed=2)
    held = np.arange(5, 35)
    at = (held[:, None] * 3 + np.arange(3)).ravel()
    n = np.tile([0.0, 0.0, 1.0], (len(held), 1))
    r = np.linalg.norm(x[held, :2] - [0.004, 0.0], axis=1)
    gap = 0.002 * (r / 0.02) ** 2 - 0.0012
    way = np.column_stack([0.6 * np.ones(len(held)), 0.1 * x[held, 1] / 0.02, -np.ones(len(held))])
    G = np.asfortranarray(G.astype(np.float32))
    args = (n, gap, way, friction, 20, 0.0005)
    eager = closure_forces(HeldColumns(G, at), *args, compiled=False, rule=rule)
    fast = closure_forces(HeldColumns(G, at), *args, compiled=True, rule=rule)
    assert (eager * n).sum(1).min() < 0  # something pushed
    np.testing.assert_allclose(fast, eager, rtol=0, atol=1e-12 * np.abs(eager).max())
    dense = closure_forces(G[np.ix_(at, at)].astype(np.float64), *args, compiled=True, rule=rule)
    np.testing.assert_allclose(dense, eager, rtol=0, atol=1e-12 * np.abs(eager).max())
    bad = G.copy(order="F")
    touched = held[np.flatnonzero(eager.any(1))[0]]
    bad[:, 3 * touched] = np.nan
    with pytest.raises(ValueError, match="G is not finite"):
        closure_forces(HeldColumns(bad, at), *args, compiled=True, rule=rule)


def _left_inside(rule: str, trials: int = 3000) -> int:
    """Of ``trials`` small random contacts (2-5 vertices of a coupled patch, each held to a
    target inside the objects and swept along the skin, friction 0.5), how many the contact
    solve settles with a vertex let go that its answer leaves inside the objects.
    """
    rng = np.random.default_rng(0)
    count = 0
    for _ in range(trials):
        a = rng.integers(2, 6)
        x = np.column_stack([rng.uniform(-0.01, 0.01, (a, 2)), np.zeros(a)])
        d = np.linalg.norm(x[:, None] - x[None], axis=-1)
        G = 1e-3 * np.kron(np.exp(-d / 0.01), np.eye(3))
        n = np.tile([0, 0, 1.0], (a, 1))
        target = np.column_stack([rng.normal(0, 1e-3, (a, 2)), -rng.uniform(0, 2e-3, a)])
        A, f = contact_forces(G, np.arange(a), n, target, 0.5, rule)
        forces = np.zeros((a, 3))
        forces[A] = f
        u = (G @ forces.ravel()).reshape(a, 3)
        off = np.setdiff1d(np.arange(a), A)
        inside = ((u[off] - target[off]) * n[off]).sum(1)  # > 0: on the objects' side
        count += bool(len(off)) and inside.max() > 1e-9
    return count


def test_the_least_energy_contact_leaves_no_vertex_inside_the_objects():
    """The contact solve by ``"least_energy"`` never leaves a vertex it let go inside the
    objects; ``"all_at_once"``, which lets go of every pulled vertex and slips every vertex past
    Coulomb's bound in one pass, does on a few of the same contacts.
    """
    assert _left_inside("least_energy") == 0
    assert _left_inside("all_at_once") == 5


def _validation_grip(i: int):
    """``(start, skin, friction)``: validation grip ``i`` of the layered forearm's grip set
    (shipped with the repository) at its first touch, the skin's held compliance and the set's
    friction coefficient.
    """
    import pathlib

    from fem.holding import HeldSkin
    from stmpl.contact.posing import first_touch
    from stmpl.data.dataset import Dataset
    from stmpl.pipeline.evaluate import scenes_of

    ds = Dataset(pathlib.Path(__file__).parents[2] / "data" / "forearm_grips")
    scenes, _ = scenes_of(ds, "val", given="pose")
    a = ds.arrays("val")
    start = first_touch(scenes[i].part, scenes[i].thickness, a["kind"][i], a["params"][i])
    skin = HeldSkin(ds.part, ds.card["config"]["tissue"])
    return start, skin, float(ds.card["config"]["friction"])


def test_a_grip_s_squeeze_grows_smoothly_as_the_hand_closes():
    """On a validation grip of the layered forearm (a tripod, shipped with the repository, its
    skin's compliance solved), the closure's squeeze rises by nearly equal steps as the hand
    closes 1.5 to 2.2 mm past its first touch under ``"least_energy"``; ``"all_at_once"``
    settles some depths otherwise than their neighbours and the squeeze falls on the way.
    """
    from fem.shapes import ROUNDING
    from stmpl.contact.posing import moved
    from stmpl.pose import within_reach

    start, skin, friction = _validation_grip(8)
    squeeze = {}
    for rule in CONTACT_RULES:
        out = []
        for depth in np.linspace(0.0015, 0.0022, 29):
            s = moved(start, depth)
            _, f = skin.closed(s.pose.gap, s.pose.way, s.thickness, friction, ROUNDING, rule)
            out.append(-(f * s.part.normals).sum())
        squeeze[rule] = np.diff(out)
    steady = squeeze["least_energy"]
    assert steady.min() > 0.9 * steady.mean() and steady.max() < 1.1 * steady.mean()
    assert squeeze["all_at_once"].min() < 0

    # the compiled steps settle as NumPy's, on the grip, by either rule
    s = moved(start, 0.0022)
    _, store = skin.store(s.thickness)
    H = np.flatnonzero(within_reach(s.pose.gap) & store.free)
    store.solve(H)
    at = (H[:, None] * 3 + np.arange(3)).ravel()
    args = (s.part.normals[H], s.pose.gap[H], s.pose.way[H], friction, 20, ROUNDING)
    for rule in CONTACT_RULES:
        eager = closure_forces(HeldColumns(store.G, at), *args, compiled=False, rule=rule)
        fast = closure_forces(HeldColumns(store.G, at), *args, compiled=True, rule=rule)
        assert (eager * s.part.normals[H]).sum() < -1.0  # a squeeze of over 1 N
        np.testing.assert_allclose(fast, eager, rtol=0, atol=1e-10 * np.abs(eager).max())


def test_a_grip_s_closure_is_continuous_where_its_contact_meets_coulomb_s_bound():
    """On a validation grip (a tripod 0.7 along the forearm, 5 N), the pose read in float32 as
    a model reads it, two vertices pass Coulomb's bound by nearly equal margins at the last
    step 4.2276833 mm past the first touch; one nanometre further the closure's skin moves by
    less than 1e-5 mm (a rule settling the vertex furthest past the bound first moved it there
    by 0.10 mm, 0.045 N).
    """
    from fem.shapes import ROUNDING
    from stmpl.contact.posing import moved

    start, skin, friction = _validation_grip(14)
    out = []
    for depth in (4.2276833e-3, 4.2276834e-3):
        s = moved(start, depth)
        read = [np.asarray(x, np.float32).astype(np.float64) for x in (s.pose.gap, s.pose.way)]
        thickness = s.thickness.astype(np.float32).astype(np.float64)
        out.append(skin.closed(*read, thickness, friction, ROUNDING))
    (u0, f0), (u1, f1) = out
    assert np.linalg.norm(f0, axis=1).sum() > 1.0  # a squeeze of over 1 N
    assert np.abs(u1 - u0).max() < 1e-8
    assert np.abs(f1 - f0).max() < 1e-5
