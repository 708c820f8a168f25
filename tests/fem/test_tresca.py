"""Contact forces within friction disks (fem/tresca.py): the closed form of one isotropic
vertex, the optimality conditions of contact on a coupled patch, Coulomb's bound at the lagged
fixed point, and an answer that moves continuously with its targets.
"""

import numpy as np
import pytest

import fem.tresca as tresca
from fem.closure import contact_forces
from fem.tresca import SMALL, coulomb_forces, coulomb_loop, pushes, within_disks
from stmpl import jit
from stmpl.failures import PredictionFailed

Z = np.array([0.0, 0.0, 1.0])


def _patch(a: int, seed: int):
    """A coupled patch of ``a`` vertices on a plane (compliance m/N), targets inside the
    objects and swept along the skin (m).
    """
    rng = np.random.default_rng(seed)
    x = np.column_stack([rng.uniform(-0.01, 0.01, (a, 2)), np.zeros(a)])
    d = np.linalg.norm(x[:, None] - x[None], axis=-1)
    G = 1e-3 * np.kron(np.exp(-d / 0.01), np.eye(3))
    n = np.tile(Z, (a, 1))
    target = np.column_stack([rng.normal(0, 1e-3, (a, 2)), -rng.uniform(-0.5e-3, 2e-3, a)])
    return G, n, target


def _tangential(v, n):
    return v - (v * n).sum(1, keepdims=True) * n


def test_one_isotropic_vertex_takes_its_target_force_cut_to_the_disk():
    """Under ``G = c I`` the least-energy force is the sticking force ``t / c`` with its
    push clamped at zero and its tangential part cut to the disk (Tresca's disk holds where
    nothing pushes; Coulomb's lagged radius, ``mu`` times the push, takes it away).
    """
    c = 1e-3
    for t, b, expect in [
        ([0.3e-3, 0.0, -1e-3], 0.5, [0.3, 0.0, -1.0]),  # within the disk: sticks
        ([2e-3, 0.0, -1e-3], 0.5, [0.5, 0.0, -1.0]),  # past it: on the rim, along the pull
        ([0.0, 1e-3, 1e-3], 0.5, [0.0, 0.5, 0.0]),  # outside the objects: no push
    ]:
        f = within_disks(c * np.eye(3), Z[None], np.array([t]), np.array([b]), np.zeros((1, 3)))
        np.testing.assert_allclose(f[0], expect, atol=1e-10)
        f = coulomb_forces(c * np.eye(3), Z[None], np.array([t]), 0.5, np.zeros((1, 3)))
        push = max(-t[2] / c, 0.0)
        cut = np.array(t[:2]) / c * min(1.0, 0.5 * push / max(np.hypot(*t[:2]) / c, 1e-300))
        np.testing.assert_allclose(f[0], [*cut, -push], atol=1e-10)


def test_on_a_coupled_patch_the_forces_meet_the_conditions_of_contact():
    """Pushed vertices lie on the surface, those let go outside it; within its disk a vertex
    sticks at its target, on the rim it slides against its force.
    """
    checked = {"stick": 0, "slide": 0, "off": 0}
    for seed in range(40):
        G, n, t = _patch(8, seed)
        b = np.random.default_rng(seed).uniform(0.0, 3.0, 8)
        f = within_disks(G, n, t, b, np.zeros((8, 3)))
        r = (G @ f.ravel()).reshape(-1, 3) - t  # displacement less target, m
        p = pushes(f, n)
        ft, rt = np.linalg.norm(_tangential(f, n), axis=1), _tangential(r, n)
        scale = 1e-7 * np.abs(t).max()
        on = p > 1e-9
        assert (p >= 0).all() and (ft <= b + 1e-12).all()
        assert np.abs((r * n).sum(1)[on]).max(initial=0) < scale
        assert ((r * n).sum(1)[~on] <= scale).all()  # let go: outside the objects
        stick = on & (ft < b - 1e-6)
        assert np.abs(rt[stick]).max(initial=0) < scale
        slide = on & (ft > b - 1e-9) & (b > 1e-3)
        for i in np.flatnonzero(slide):
            cos = rt[i] @ _tangential(f, n)[i] / (np.linalg.norm(rt[i]) * ft[i] + 1e-300)
            assert np.linalg.norm(rt[i]) < scale or cos < -0.999999
        checked["stick"] += stick.sum()
        checked["slide"] += slide.sum()
        checked["off"] += (~on).sum()
    assert min(checked.values()) > 20  # every state met often


def test_coulomb_holds_at_the_lagged_fixed_point():
    """Four passes of lagged radii: no tangential force past ``mu`` times its push, and the
    forces of the last pass within 1 % of the pass before (the lag has settled).
    """
    for seed in range(20):
        G, n, t = _patch(6, seed)
        f = coulomb_forces(G, n, t, 0.5, np.zeros((6, 3)))
        ft = np.linalg.norm(_tangential(f, n), axis=1)
        assert (ft <= 0.5 * pushes(f, n) * (1 + 1e-12) + 1e-15).all()
        again = within_disks(G, n, t, 0.5 * pushes(f, n), f)
        assert np.abs(again - f).max() <= 0.01 * np.abs(f).max()


def test_the_answer_moves_continuously_with_its_targets():
    """Targets (some 1e-3 m) moved by 1e-12 m move the contact's forces by less than 1e-6 of
    their size on every patch, whichever vertices stick, slide or are let go.
    """
    for seed in range(200):
        G, n, t = _patch(5, seed)
        nudge = 1e-12 * np.random.default_rng(1000 + seed).normal(size=t.shape)
        out = []
        for target in (t, t + nudge):
            A, f = contact_forces(G, np.arange(5), n, target, 0.5, "least_energy")
            full = np.zeros((5, 3))
            full[A] = f
            out.append(full)
        assert np.abs(out[0] - out[1]).max() <= 1e-6 * np.abs(out[0]).max()


def test_a_pass_that_does_not_settle_is_refused_as_a_failed_prediction(monkeypatch):
    """Too few iterations, or a compliance that is not definite (the forces run off to
    infinity): the pass is refused with its reason as a failed prediction, which force control
    and the evaluation count, not as bad input.
    """
    G, n, t = _patch(6, 0)
    monkeypatch.setattr(tresca, "ITERATIONS", 2)
    with pytest.raises(PredictionFailed, match="did not settle in 2 iterations"):
        within_disks(G, n, t, np.full(6, 0.1), np.zeros((6, 3)))
    monkeypatch.setattr(tresca, "ITERATIONS", 20000)
    with pytest.raises(tresca.NotSettled, match="not finite"), np.errstate(all="ignore"):
        indefinite = 1e-3 * np.diag(np.tile([1.0, 1.0, -1.0], 6))  # pushing opens the skin
        within_disks(indefinite, n, t, np.full(6, 0.1), np.zeros((6, 3)))


@pytest.mark.parametrize("compiled", [False, True])
def test_a_force_let_go_whose_push_rounds_below_zero_gives_no_disk(compiled):
    """A vertex let go the step before keeps at most a tangential part, and its push ``-f . n``
    rounds to a few 1e-17 of it either way. Lagged from such a force, a disk's radius below
    zero (once projecting a zero tangential force onto it divided by zero, and the forces
    turned NaN on a 10 N whole-hand grip) is no disk: the forces answer as from no force.
    """
    G, n, t = _patch(7, 3)
    before = np.zeros((7, 3))
    before[2] = 1e-179 * n[2]  # pulling by a rounding: a push of -1e-179 N
    before[4] = 1e-3 * _tangential(np.array([[0.3, 0.8, 0.1]]), n[4:5])[0]
    assert pushes(before, n)[2] < 0
    solve = coulomb_forces
    if compiled:
        compile_ = jit.njit(error_model="numpy")
        if compile_ is None:
            pytest.skip("Numba is not installed")
        solve = coulomb_loop(compile_)
    f = solve(G, n, t, 0.5, before)
    assert np.isfinite(f).all()
    clean = before.copy()
    clean[2] = 0.0
    np.testing.assert_array_equal(f, solve(G, n, t, 0.5, clean))


@pytest.mark.parametrize("size", [7, 20])
@pytest.mark.parametrize("friction", [0.0, 0.5, np.inf])
def test_the_compiled_solve_answers_as_the_numpy_one(friction, size):
    """The compiled pass, its product by ``G`` in its own loop (7 vertices, up to
    :data:`fem.tresca.SMALL` DOFs) or in BLAS (20), answers as NumPy's.
    """
    assert 3 * 7 <= SMALL < 3 * 20
    compile_ = jit.njit(error_model="numpy")
    if compile_ is None:
        pytest.skip("Numba is not installed")
    coulomb = coulomb_loop(compile_)
    for seed in range(5):
        G, n, t = _patch(size, seed)
        start = np.zeros((size, 3))
        eager = coulomb_forces(G, n, t, friction, start)
        fast = coulomb(G, n, t, friction, start)
        np.testing.assert_allclose(fast, eager, rtol=0, atol=1e-12 * np.abs(eager).max())
