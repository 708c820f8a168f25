"""The compliance operator is the linear FEM: superposition of its columns reproduces a direct
solve, and it is the tangent of the Neo-Hookean solve at rest.
"""

import numpy as np
import pytest

from fem.compliance import compliance, sparsify, unit_loads
from fem.material import LinearElastic, NeoHookean
from fem.mesh import shell_mesh
from fem.solver import Solver
from stmpl.body.primitives import sheet, tube

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
    assert np.abs(u).max() > 1e-4  # tenths of a mm: a real response
    np.testing.assert_allclose(np.einsum("ijc,j->ic", G, f), u, atol=1e-6 * np.abs(u).max())


def test_it_is_the_neo_hookean_tangent_at_rest(part, G, rng):
    f = _load(part, rng) * 0.01  # a light touch: within 0.1 % of linear
    mesh = shell_mesh(part, np.full(part.n_vertices, 0.008), layers=1, subdivisions=1)
    sol = Solver(mesh, NeoHookean(), order=1).solve(f)
    u = sol.part_displacement(mesh)
    err = np.abs(np.einsum("ijc,j->ic", G, f) - u).max() / np.abs(u).max()
    assert err < 1e-3


def test_reciprocity_and_blocks(part, G):
    """Maxwell-Betti: the normal response at i to a normal push at j equals that at j to i
    (the traction spreading is symmetric on a uniform tube), the fixed rims do not move, and the
    block size does not change the operator.
    """
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


def test_local_columns_match_the_whole_part():
    """A column solved on the patch it moves equals the whole part's within the ring
    tolerance's reach; rows outside the patch are zero, columns come back in the asked order.
    """
    from fem.compliance import local_compliance

    long = tube(radius=0.05, length=0.4, n_around=24, n_along=24)
    mid = int(np.argmin(np.abs(long.vertices[:, 2] - 0.2)))
    cols = [mid + 1, mid]
    whole = compliance(long, 0.004, RES, NeoHookean(), columns=cols)
    g, info = local_compliance(long, 0.004, cols, RES, NeoHookean(), tolerance=0.01)
    assert g.shape == (long.n_vertices, 2, 3)
    assert info["vertices"] < long.n_vertices / 2  # a patch, not the whole tube
    for k in range(2):
        err = np.linalg.norm(g[:, k] - whole[:, k], axis=1).max()
        assert err <= 0.01 * np.linalg.norm(whole[:, k], axis=1).max()
    with pytest.raises(ValueError, match="vertex indices"):
        local_compliance(long, 0.004, [long.n_vertices], RES, NeoHookean())


def test_column_store_computes_once_and_reads_its_cache(part, G, tmp_path, monkeypatch):
    from fem.compliance import ColumnStore

    monkeypatch.setenv("STMPL_CACHE_DIR", str(tmp_path))
    setup = {"material": {"name": "neo_hookean", "E": 1000.0, "nu": 0.4}, "resolution": RES}
    store = ColumnStore(part, setup, [0.008])
    a = store.columns(0, [50, 60])
    assert store.ensure(0, [60, 50]) == 0 and store.computed == 2  # nothing solved again
    np.testing.assert_allclose(a[:, 0], G[:, 50], atol=0.01 * np.abs(G[:, 50]).max())
    back = ColumnStore(part, setup, [0.008])  # a new process: from disk
    assert back.missing(0, [50, 60, 61]).tolist() == [61]
    np.testing.assert_array_equal(back.columns(0, [50, 60]), a)
    one, two = ColumnStore(part, setup, [0.008]), ColumnStore(part, setup, [0.008])
    one.ensure(0, [70])  # two processes at once:
    two.ensure(0, [80])  # neither loses the other's
    assert ColumnStore(part, setup, [0.008]).missing(0, [50, 60, 70, 80]).size == 0
    back.path(0).write_bytes(b"not an npz")  # a broken file: recomputed
    assert ColumnStore(part, setup, [0.008]).missing(0, [50]).tolist() == [50]


def test_a_warmed_store_solved_nothing_of_its_own_and_warms_once(part, tmp_path, monkeypatch):
    """:meth:`ColumnStore.warm` runs the set-up's solve on a tiny patch (its compiled code
    loaded in the caller's thread), once per set-up and process, and leaves the store and its
    cache as they were.
    """
    from fem import compliance as mod

    monkeypatch.setenv("STMPL_CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(mod, "_WARMED", set())
    setup = {"material": {"name": "neo_hookean", "E": 1000.0, "nu": 0.4}, "resolution": RES}
    store = mod.ColumnStore(part, setup, [0.008])
    assert store.warm() > 0 and store.computed == 0 and not store.path(0).exists()
    assert mod.ColumnStore(part, setup, [0.008]).warm() == 0.0
    other = {**setup, "material": {"name": "neo_hookean", "E": 2000.0, "nu": 0.4}}
    assert mod.ColumnStore(part, other, [0.008]).warm() > 0


def test_a_layered_tissue_s_operator_is_its_fem_s_tangent_at_rest(part):
    """The forearm preset's linear FEM (skin, fat and muscle meshed as the FEM meshes them): a
    press on one vertex answered by its column differs from the layered FEM's answer by an
    amount that vanishes with the load, in proportion to it (0.6 % of the deepest at 10 mN, three
    times that at 30 mN on a tube); its on-demand patch gives the same column.
    """
    from fem.compliance import fem_setup, local_compliance
    from fem.simulate import simulate

    res = {"subdivisions": 1, "layers": 2, "order": 2, "refine_radius": None}
    t = np.full(part.n_vertices, 0.0075)
    j = int(np.argmin(np.linalg.norm(part.vertices - [0.04, 0, 0.1], axis=1)))
    (g,) = compliance(part, t, res, columns=[j], tissue="forearm").transpose(1, 0, 2)
    f = np.zeros(part.n_vertices)
    f[j] = 1.0
    mesh, sols = simulate(part, t, f, [0.01, 0.03], res, tissue="forearm")
    off = [
        np.abs(s.part_displacement(mesh) - g * total).max() / np.abs(g * total).max()
        for s, total in zip(sols, [0.01, 0.03])
    ]
    assert off[0] < 0.01 and 2.5 < off[1] / off[0] < 3.5, off
    local, _ = local_compliance(part, 0.0075, [j], res, tissue="forearm")
    assert np.abs(local[:, 0] - g).max() < 2e-3 * np.abs(g).max()
    with pytest.raises(ValueError, match="brings its own laws"):
        compliance(part, t, res, NeoHookean(), columns=[j], tissue="forearm")
    setup = fem_setup({"tissue": "forearm", "body": {"phenotype": {"weight": 0.7}}})
    assert setup["tissue"] == "forearm" and setup["phenotype"] == {"weight": 0.7}
    assert "tissue" not in fem_setup({"tissue": "paper"})  # the gel's set-ups read as before


@pytest.mark.parametrize("order", [1, 2])
def test_force_columns_are_unit_loads_on_the_free_dofs(order):
    part = sheet(0.1, 0.1, 7, 7)
    mesh = shell_mesh(part, np.full(part.n_vertices, 0.005), layers=1)
    S = Solver(mesh, order=order)
    cols = np.array([24, 3, 31])
    B = unit_loads(S, cols)
    assert B.shape == (len(S.free), 3) and B.flags.f_contiguous
    for k, j in enumerate(cols):
        e = np.zeros(part.n_vertices)
        e[j] = 1.0
        f = S.external_forces(e)
        np.testing.assert_allclose(f.sum(0), [0.0, 0.0, -1.0], atol=1e-12)
        np.testing.assert_array_equal(B[:, k], f.ravel()[S.free])
