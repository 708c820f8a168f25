"""The skin held where an object holds it and the rest answered by the linear FEM
(fem/holding.py): against the same linear FEM solved with those nodes fixed, on a part and on
its subdivision.
"""

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.sparse.linalg import spsolve

from fem.holding import Holding, SkinCompliance, held_block, held_factor
from stmpl.body import tube

RES = {"subdivisions": 0, "layers": 1, "order": 2}


@pytest.fixture(scope="module")
def part():
    return tube(radius=0.03, length=0.08, n_around=12, n_along=6)


def _held_and_target(part):
    """A patch of the tube's skin pushed in and dragged round it, 1-2 mm."""
    x = part.vertices
    held = np.flatnonzero((np.abs(x[:, 2] - 0.04) < 0.02) & (x[:, 0] > 0.015))
    u = np.zeros((part.n_vertices, 3))
    u[held] = -0.001 * part.normals[held] + [0.0, 0.002, 0.0]
    return held, u


def _fixed_solve(h: Holding, held, u) -> np.ndarray:
    """The same linear FEM with the held vertices' nodes fixed at ``u``: ``K_FF x = -K_FH u_H``."""
    s = h.solver
    z = np.zeros((s.n_all, 3))
    _, K = s.assemble(z, z)
    if sp.tril(K, -1).nnz == 0:  # the solver keeps the upper triangle (symmetric PARDISO)
        K = K + sp.triu(K, 1).T
    K = K.tocsr()
    dof = np.full(s.n_all * 3, -1)
    dof[s.free] = np.arange(len(s.free))
    H = dof[(h.nodes[held][:, None] * 3 + np.arange(3)).ravel()]
    F = np.setdiff1d(np.arange(len(s.free)), H)
    x = np.zeros(len(s.free))
    x[H] = u[held].ravel()
    x[F] = spsolve(K[F][:, F].tocsc(), -K[F][:, H] @ x[H])
    full = np.zeros(s.n_all * 3)
    full[s.free] = x
    return full.reshape(s.n_all, 3)[h.nodes]


def test_the_held_skin_stays_and_the_rest_is_the_fixed_linear_fem_s(part):
    """Held vertices come back where they were held; every other vertex where the linear FEM
    with those nodes fixed puts it (a Dirichlet solve, not the compliance's Schur complement),
    within round-off; and the answer moves far from the held patch.
    """
    h = Holding(part, 0.0075, RES, "forearm")
    held, u = _held_and_target(part)
    got = h.answer(held, u)
    np.testing.assert_allclose(got[held], u[held], atol=1e-12)
    want = _fixed_solve(h, held, u)
    assert np.abs(got - want).max() < 1e-6 * np.abs(u).max()
    free = np.setdiff1d(np.arange(part.n_vertices), held)
    assert np.linalg.norm(got[free], axis=1).max() > 0.1 * np.abs(u).max()


def test_a_subdivided_part_is_held_and_answered_on_its_own_vertices(part):
    """On the tube subdivided once, meshed on the tube it came from (its vertices are the
    quadratic elements' nodes), a held edge midpoint stays and the answer is the fixed solve's.
    """
    fine = part.subdivided(1)
    h = Holding(fine, 0.0075, RES, "forearm")
    assert h.unknowns == Holding(part, 0.0075, RES, "forearm").unknowns
    held, u = _held_and_target(fine)
    assert (held >= part.n_vertices).any()  # midpoints among them
    got = h.answer(held, u)
    np.testing.assert_allclose(got[held], u[held], atol=1e-12)
    assert np.abs(got - _fixed_solve(h, held, u)).max() < 1e-6 * np.abs(u).max()


def test_bad_holds_are_named(part):
    h = Holding(part, 0.0075, RES, "forearm")
    held, u = _held_and_target(part)
    rim = part.rims[0][0]
    for args, message in [
        (([], u), "no vertex is held"),
        (([part.n_vertices], u), "held vertices must be indices"),
        ((held, u[:-1]), r"displacement must be \(N, 3\)"),
        ((held, np.where(np.isin(np.arange(len(u)), held)[:, None], u, np.nan)), None),
        ((held, np.full_like(u, np.nan)), "not finite"),
        (([rim], u), "held by the mesh itself"),
    ]:
        if message is None:  # the rows not held are not read
            assert np.isfinite(h.answer(*args)).all()
            continue
        with pytest.raises(ValueError, match=message):
            h.answer(*args)
    with pytest.raises(ValueError, match="finite and positive"):
        Holding(part, -0.001, RES, "forearm")
    with pytest.raises(ValueError, match="quadratic elements"):
        Holding(part, 0.0075, {"subdivisions": 0, "layers": 1, "order": 1}, "paper")


def test_the_skin_compliance_is_solved_once_and_read_back_from_the_cache(part):
    """:class:`SkinCompliance`: the columns asked for are the holding's own (float32), solved
    once (a second ask solves none), and a second store of the same set-up reads them from the
    disk cache (a broken cache file is solved again); another thickness is another store; a rim
    vertex is refused by name.
    """
    h = Holding(part, 0.0065, RES, "forearm")  # a thickness no other test caches
    held, _ = _held_and_target(part)
    s = SkinCompliance(part, 0.0065, "forearm")
    got = s.columns(held)
    np.testing.assert_allclose(got, h.columns(held), rtol=1e-6, atol=1e-6 * np.abs(got).max())
    assert s.solve(held) == 0 and s.done.sum() == len(held)
    again = SkinCompliance(part, 0.0065, "forearm")
    assert again.done.sum() == len(held) and again.missing(held).size == 0
    np.testing.assert_array_equal(again.columns(held), got)
    assert SkinCompliance(part, 0.0085, "forearm").done.sum() == 0
    again.path.write_bytes(b"not a cache")  # a broken file: nothing read, solved again
    broken = SkinCompliance(part, 0.0065, "forearm")
    assert broken.done.sum() == 0 and np.abs(broken.G).max() == 0
    np.testing.assert_array_equal(broken.columns(held), got)
    with pytest.raises(ValueError, match="held by the mesh itself"):
        s.columns([part.rims[0][0]])


@pytest.mark.parametrize("compiled", [False, True])
def test_a_held_factor_is_float32_where_it_can_be_and_float64_where_not(monkeypatch, compiled):
    """The factor of ``G[at, at]`` made symmetric: of a well-conditioned block in float32
    (``L L^T`` within float32's rounding of it); of a badly conditioned one (condition number
    1e6 or 1e9) in float64, exact, even where float32's factorisation meets no negative pivot;
    of a singular one with its diagonal lifted by 1e-7 of its mean, not refused; the same with
    the block read in place (compiled, where Numba is loaded) as gathered by NumPy.
    """
    import stmpl.jit

    monkeypatch.setattr(stmpl.jit, "loaded", lambda: compiled)
    rng = np.random.default_rng(2)
    Q, _ = np.linalg.qr(rng.normal(size=(40, 40)))
    at = np.sort(rng.choice(100, 40, replace=False))

    def compliance(A):  # A at ``at`` of a float32 compliance, a little asymmetric elsewhere
        G = rng.normal(size=(100, 100)).astype(np.float32)
        G[np.ix_(at, at)] = A
        return np.asfortranarray(G)

    for low, dtype, tol in [(1e-2, np.float32, 1e-6), (1e-6, np.float64, 1e-12), (1e-9, None, 0)]:
        G = compliance((Q * np.geomspace(low, 1.0, 40)) @ Q.T)
        A = held_block(G, at)
        np.testing.assert_array_equal(A, A.T)
        L = held_factor(G, at)
        assert L.dtype == (dtype or np.float64)
        assert np.abs(np.tril(L) - L).max() == 0
        if dtype is not None:
            assert np.abs(L.astype(np.float64) @ L.T - A).max() < tol
    G = compliance((Q * np.r_[0.0, np.ones(39)]) @ Q.T)
    A = held_block(G, at)
    L = held_factor(G, at)
    assert np.abs(L @ L.T - (A + 1e-7 * A.diagonal().mean() * np.eye(40))).max() < 1e-6
    assert held_factor(G, at[:0]).shape == (0, 0)  # no object near


def test_forgetting_the_poses_forgets_their_held_factors(part):
    """:meth:`HeldSkin.forget_poses`: a pose's held set factorised again after it (a moving
    object meets a new held set at nearly every answer: a timed answer must pay for it).
    """
    from fem.holding import HeldSkin

    skin = HeldSkin(part, "forearm")
    t = np.full(part.n_vertices, 0.0075)
    gap = np.full(part.n_vertices, 1.0)
    held, _ = _held_and_target(part)
    gap[held] = -0.001
    first = skin.hold(gap, t)[2]
    assert skin.hold(gap, t)[2] is first  # kept
    skin.forget_poses()
    again = skin.hold(gap, t)[2]
    assert again is not first
    np.testing.assert_array_equal(again, first)


def test_the_pushed_skin_moves_as_told_on_the_held_set_and_by_the_forces_everywhere(part):
    """:meth:`HeldSkin.push`: moves alone stay on the held vertices; a force of 1 N on a held
    DOF (its answer ``PUSH_SPREAD d_j``) moves the skin by the compliance's column, by ``d_j``
    (m/N) at that DOF itself, within half a step of its 16-bit copy (:mod:`fem.columns`), and
    as much at DOF ``i`` as a force at ``i`` moves ``j`` (Maxwell-Betti); the two add; no
    object near, no motion.
    """
    from fem.columns import STEPS
    from fem.holding import PUSH_SPREAD, HeldSkin

    skin = HeldSkin(part, "forearm")
    t = np.full(part.n_vertices, 0.0075)
    gap = np.full(part.n_vertices, 1.0)
    held, _ = _held_and_target(part)
    gap[held] = -0.001
    s, at, d = skin.pushing(gap, t)
    np.testing.assert_array_equal(at[::3] // 3, held)
    rng = np.random.default_rng(0)
    r = np.zeros((part.n_vertices, 3))
    r[held] = rng.normal(0, 1e-3, (len(held), 3))
    zero = np.zeros_like(r)
    np.testing.assert_allclose(skin.push(r, zero, gap, t), r, atol=1e-12)
    i, j = at[4], at[-2]

    def pushed_at(k):
        forces = np.zeros(3 * part.n_vertices)
        forces[k] = PUSH_SPREAD * d[np.flatnonzero(at == k)[0]]
        return skin.push(zero, forces.reshape(-1, 3), gap, t).ravel()

    ui, uj = pushed_at(i), pushed_at(j)
    step = float(np.abs(s.G[:, j]).max()) / STEPS  # the column's 16-bit step (fem.columns)
    np.testing.assert_allclose(uj, s.G[:, j], rtol=0, atol=0.5 * step + 1e-6 * abs(s.G[j, j]))
    assert uj[j] == pytest.approx(d[np.flatnonzero(at == j)[0]], abs=0.5 * step)
    assert ui[j] == pytest.approx(uj[i], rel=2e-3)
    both = np.zeros(3 * part.n_vertices)
    both[j] = PUSH_SPREAD * d[np.flatnonzero(at == j)[0]]
    np.testing.assert_allclose(
        skin.push(r, both.reshape(-1, 3), gap, t).ravel(), r.ravel() + uj, atol=1e-9
    )
    far = np.full(part.n_vertices, 1.0)
    assert not skin.push(r, r, far, t).any()
