"""Verification of the FEM solver against closed forms, finite differences and scikit-fem."""

from dataclasses import replace

import numpy as np
import pytest

import fem.solver as fs
from fem.limits import Limits
from fem.linear_solvers import available_linear_solvers
from fem.material import (
    Demiray,
    Layered,
    LinearElastic,
    NeoHookean,
    Yeoh,
    lame,
    uniaxial,
)
from fem.mesh import shell_mesh
from fem.solver import Solver, SolverOptions
from stmpl.body.primitives import sheet, tube
from stmpl.tissue import GEL_TRUSTED_COMPRESSION


def _lame(n_around, layers, p=1.0, b=0.05, t=0.01, material=None, order=1):
    """A thick cylinder (radii b - t, b in m) under outer pressure ``p`` (Pa), inner face fixed,
    ends held axially (plane strain), with ``n_around`` vertices per ring and axial spacing tied
    to it. Returns (FEM mean outer radial displacement, closed form, max nodal error / max |u|).
    """
    part = tube(radius=b, length=0.24 / n_around, n_around=n_around, n_along=3)
    mesh = shell_mesh(part, np.full(part.n_vertices, t), layers=layers, normal_smoothing=0)
    fixed = np.zeros((mesh.n_nodes, 3), bool)
    rim = np.concatenate(part.rims)
    for k in range(layers + 1):
        fixed[rim + k * mesh.n_skin, 2] = True
    material = material or LinearElastic(1000.0, 0.4)
    sol = Solver(
        mesh, material, fixed=fixed, options=SolverOptions(rims="free"), order=order
    ).solve(p * part.vertex_areas)
    assert sol.ok, sol.reason
    mu, lam = lame(material.E, material.nu)
    a = b - t
    A = -p / (2 * (lam + mu) + 2 * mu * a**2 / b**2)  # u(r) = A r + B / r, u(a) = 0
    r = np.linalg.norm(mesh.nodes[:, :2], axis=1)
    ur = np.einsum("si,si->s", sol.displacement[:, :2], mesh.nodes[:, :2] / r[:, None])
    exact = A * (r - a**2 / r)
    skin = slice(0, mesh.n_skin)
    return ur[skin].mean(), exact[skin].mean(), np.abs(ur - exact).max() / np.abs(exact).max()


@pytest.mark.parametrize("order", [1, 2])
def test_lame_cylinder_matches_closed_form_within_2_percent(order):
    fem, exact, _ = _lame(48, 2, order=order)
    assert exact < 0  # pressure pushes inward
    assert abs(fem / exact - 1) < 0.02


def test_lame_error_falls_at_second_order():
    errs = np.array([_lame(n, L)[2] for n, L in [(48, 2), (96, 4), (192, 8)]])
    rates = np.log2(errs[:-1] / errs[1:])
    assert errs[-1] < 0.005 and rates[0] > 1.5 and rates[1] > 1.85, (errs, rates)
    # quadratic elements: smaller errors at the same mesh (the polygon's facets then dominate)
    errs2 = np.array([_lame(n, L, order=2)[2] for n, L in [(24, 1), (48, 2), (96, 4)]])
    rates2 = np.log2(errs2[:-1] / errs2[1:])
    assert np.all(errs2 < 0.4 * np.array([_lame(n, L)[2] for n, L in [(24, 1), (48, 2), (96, 4)]]))
    assert np.all(rates2 > 1.7), (errs2, rates2)


def test_neo_hookean_agrees_with_linear_elasticity_at_small_load():
    lin = _lame(48, 2, p=2.0)[0]
    nh = _lame(48, 2, p=2.0, material=NeoHookean(1000.0, 0.4))[0]
    assert abs(nh / lin - 1) < 0.01
    # and they part ways under a large load (the reason the FEM is Neo-Hookean)
    lin = _lame(24, 1, p=100.0)[0]
    nh = _lame(24, 1, p=100.0, material=NeoHookean(1000.0, 0.4))[0]
    assert abs(nh / lin - 1) > 0.03


def _small_shell(layers=2):
    part = tube(radius=0.04, length=0.08, n_around=12, n_along=5)
    return part, shell_mesh(part, np.full(part.n_vertices, 0.008), layers=layers)


YEOH = Yeoh(K=2e4, C10=400.0, C20=2000.0, C30=500.0)
DEMIRAY = Demiray(K=2e4, a=800.0, b=8.0)


def _layered(mesh, laws=(NeoHookean(), YEOH)):
    """The laws by element layer: the outer element layer the first law, the rest the second."""
    outer = np.isin(mesh.tets, np.arange(mesh.n_skin)).any(1)
    return Layered(laws, np.where(outer, 0, 1))


@pytest.mark.parametrize(
    "material,order,volume",
    [
        (NeoHookean(), 1, "auto"),
        (LinearElastic(), 1, "auto"),
        (NeoHookean(), 2, "auto"),
        (YEOH, 1, "point"),
        (DEMIRAY, 2, "point"),
        (DEMIRAY, 2, "mean"),
        ("layered", 1, "auto"),
        ("layered", 2, "auto"),
        ("tissue", 2, "mean"),
        ("mixed", 2, "auto"),
    ],
)
def test_tangent_matches_finite_differences_of_the_residual(material, order, volume):
    part, mesh = _small_shell(layers=2 if order == 1 or material == "mixed" else 1)
    amplitude = 5e-4
    if material == "layered":
        material = _layered(mesh)
    elif material == "tissue":
        material = _layered(mesh, (YEOH, DEMIRAY))
    elif material == "mixed":  # a compressible skin over a nearly incompressible layer
        material = _layered(mesh, (YEOH, Yeoh(K=2e6, C10=100.0)))
        amplitude = 1e-4  # thinner elements: the same strains from smaller displacements
    options = SolverOptions(linear_solver="superlu", volume=volume)
    S = Solver(mesh, material, options=options, order=order)
    if volume == "auto" and S.bulk is not None:  # mean dilatation where nearly incompressible
        assert (S.bulk > 0).any() and (S.point_bulk > 0).any()
        assert not ((S.bulk > 0) & (S.point_bulk > 0)).any()
    else:
        assert (S.bulk is not None) == (volume == "mean")
    rng = np.random.default_rng(1)
    u = np.zeros((S.n_all, 3))
    u.reshape(-1)[S.free] = rng.normal(0, amplitude, len(S.free))
    d = np.zeros_like(u)
    d.reshape(-1)[S.free] = rng.normal(0, 1, len(S.free))
    K = S.tangent_full(u)
    h = 1e-7
    zero = np.zeros_like(u)
    fd = (S.residual(u + h * d, zero) - S.residual(u - h * d, zero)).reshape(-1)[S.free] / (2 * h)
    Kd = K @ d.reshape(-1)[S.free]
    assert np.linalg.norm(fd - Kd) < 1e-6 * np.linalg.norm(Kd)
    assert abs(K - K.T).max() < 1e-12 * abs(K).max()
    # the residual is the energy's gradient
    dE = (S.energy(u + h * d, zero) - S.energy(u - h * d, zero)) / (2 * h)
    assert dE == pytest.approx(np.vdot(S.residual(u, zero), d), rel=1e-6)


def test_the_definite_tangent_adds_only_the_pressure_stiffness_s_negative_part_back():
    """Under mean dilatation the fallback tangent replaces each point's pressure stiffness by
    its positive part, so it exceeds the full tangent by a positive semi-definite matrix and is
    positive definite where the full one is not (pressures far above the shear modulus).
    """
    part, mesh = _small_shell(layers=1)
    soft = Demiray(K=2e6, a=50.0, b=8.0)  # fat-like: shear modulus 50 Pa, nearly incompressible
    S = Solver(mesh, soft, options=SolverOptions(linear_solver="superlu", volume="mean"), order=2)
    rng = np.random.default_rng(4)
    u = np.zeros((S.n_all, 3))
    u.reshape(-1)[S.free] = rng.normal(0, 2e-4, len(S.free))
    zero = np.zeros_like(u)
    full = S.assemble(u, zero)[1].toarray()
    definite = S.assemble(u, zero, definite=True)[1].toarray()
    scale = np.abs(full).max()
    assert np.linalg.eigvalsh(definite - full).min() > -1e-9 * scale
    assert np.linalg.eigvalsh(full).min() < 0 < np.linalg.eigvalsh(definite).min()


def test_assembly_matches_scikit_fem():
    skfem = pytest.importorskip("skfem")
    from skfem.models.elasticity import linear_elasticity

    part, mesh = _small_shell(layers=1)
    m = skfem.MeshTet(mesh.nodes.T, mesh.tets.T)
    basis = skfem.Basis(m, skfem.ElementVector(skfem.ElementTetP1()))
    E, nu = 1000.0, 0.4
    mu, lam = lame(E, nu)
    # linear elasticity at rest
    K_sk = skfem.asm(linear_elasticity(lam, mu), basis).tocsr()
    S = Solver(mesh, LinearElastic(E, nu), options=SolverOptions(linear_solver="superlu"))
    K = S.tangent_full(np.zeros((mesh.n_nodes, 3)))
    Kf = K_sk[S.free][:, S.free]
    assert abs(K - Kf).max() < 1e-10 * abs(Kf).max()

    # Neo-Hookean residual and tangent at a deformed state, through fem.skfem_forms
    from fem.skfem_forms import assemble

    rng = np.random.default_rng(2)
    u = np.zeros((mesh.n_nodes, 3))
    u.reshape(-1)[S.free] = rng.normal(0, 5e-4, len(S.free))
    r_sk, K_sk = assemble(mesh.nodes, mesh.tets, u, mu, lam)
    K_sk = K_sk[S.free][:, S.free]
    S = Solver(mesh, NeoHookean(E, nu), options=SolverOptions(linear_solver="superlu"))
    r = S.residual(u, np.zeros_like(u)).reshape(-1)
    np.testing.assert_allclose(r, r_sk, atol=1e-10 * abs(r_sk).max())
    K = S.tangent_full(u)
    assert abs(K - K_sk).max() < 1e-10 * abs(K_sk).max()


def test_quadratic_assembly_matches_scikit_fem():
    skfem = pytest.importorskip("skfem")
    from scipy.spatial import cKDTree
    from skfem.models.elasticity import linear_elasticity

    part, mesh = _small_shell(layers=1)
    E, nu = 1000.0, 0.4
    mu, lam = lame(E, nu)
    S = Solver(mesh, LinearElastic(E, nu), options=SolverOptions(linear_solver="superlu"), order=2)
    m = skfem.MeshTet(mesh.nodes.T, mesh.tets.T)
    basis = skfem.Basis(m, skfem.ElementVector(skfem.ElementTetP2()))
    K_sk = skfem.asm(linear_elasticity(lam, mu), basis).tocsr()
    # match scikit-fem's DOFs to ours by position and component
    ours = np.concatenate([mesh.nodes, mesh.nodes[S.edges].mean(1)])
    locs = basis.doflocs.T  # (3 * nodes, 3)
    node = cKDTree(ours).query(locs)[1]
    comp = np.zeros(len(locs), dtype=int)
    for c in range(3):
        comp[basis.nodal_dofs[c]] = c
        comp[basis.edge_dofs[c]] = c
    perm = np.empty(len(locs), dtype=int)
    perm[3 * node + comp] = np.arange(len(locs))
    assert len(np.unique(perm)) == len(perm)
    Kf = K_sk[perm][:, perm][S.free][:, S.free]
    K = S.tangent_full(np.zeros((S.n_all, 3)))
    assert abs(K - Kf).max() < 1e-10 * abs(Kf).max()


def test_quadratic_pressure_loads_keep_the_total():
    part = sheet(0.1, 0.1, 7, 7)
    mesh = shell_mesh(part, np.full(part.n_vertices, 0.005), layers=1)
    force = np.zeros(part.n_vertices)
    force[[24, 25, 31]] = [0.2, 0.1, 0.3]
    f = Solver(mesh, order=2).external_forces(force)
    np.testing.assert_allclose(f.sum(0), [0.0, 0.0, -0.6], atol=1e-12)
    assert np.abs(f[:, :2]).max() == 0


def test_linear_solvers_agree():
    part, mesh = _small_shell()
    force = np.zeros(part.n_vertices)
    force[20:23] = 0.05
    ref = None
    for name in available_linear_solvers():
        sol = Solver(mesh, options=SolverOptions(linear_solver=name)).solve(force)
        assert sol.ok, (name, sol.reason)
        if ref is None:
            ref = sol.displacement
        # within the Newton tolerance (rtol 1e-7): each solver's steps are solved to its own
        # round-off, and CG with its factorisation to a thousandth
        np.testing.assert_allclose(sol.displacement, ref, atol=1e-7 * np.abs(ref).max())


@pytest.mark.parametrize("order", [1, 2])
def test_continuation_warm_start_matches_a_cold_solve(order):
    part = sheet(0.1, 0.1, 9, 9)
    mesh = shell_mesh(part, np.full(part.n_vertices, 0.01), layers=2 if order == 1 else 1)
    force = np.zeros(part.n_vertices)
    force[40] = 1.0
    S = Solver(mesh, order=order)
    sols = S.continuation(force, [0.05, 0.1, 0.15])
    assert all(s.ok for s in sols)
    assert [s.total_force for s in sols] == pytest.approx([0.05, 0.1, 0.15])
    cold = S.solve(force * 0.15)
    np.testing.assert_allclose(
        sols[-1].displacement, cold.displacement, atol=1e-6 * np.abs(cold.displacement).max()
    )
    assert sols[-1].iterations < cold.iterations
    # deeper press, more displacement, the centre moves down
    d = [-s.part_displacement(mesh)[40, 2] for s in sols]
    assert 0 < d[0] < d[1] < d[2]


def test_a_failed_solve_reports_why_and_returns_no_displacement():
    part = sheet(0.1, 0.1, 9, 9)
    mesh = shell_mesh(part, np.full(part.n_vertices, 0.005), layers=2)
    force = np.zeros(part.n_vertices)
    force[40] = 1.0
    sols = Solver(mesh, options=SolverOptions(max_substeps=1)).continuation(
        force, [0.05, 50.0, 60.0]
    )
    assert sols[0].ok
    assert not sols[1].ok and sols[1].displacement is None and sols[1].reason
    assert not sols[2].ok and sols[2].reason.startswith("skipped")
    with pytest.raises(RuntimeError, match="failed"):
        sols[1].part_displacement(mesh)


def test_non_physical_states_are_rejected():
    part = sheet(0.1, 0.1, 9, 9)
    mesh = shell_mesh(part, np.full(part.n_vertices, 0.01), layers=2)
    force = np.zeros(part.n_vertices)
    force[40] = 0.1
    ok = Solver(mesh).solve(force)
    assert ok.ok and 0 < ok.max_compression < 1
    strict = Solver(mesh, options=SolverOptions(max_compression=0.5 * ok.max_compression))
    bad = strict.solve(force)
    assert not bad.ok and "non-physical" in bad.reason and bad.displacement is None


def test_the_gel_is_trusted_up_to_where_it_was_measured_to_buckle():
    """The paper's gel carries its own bound (:data:`stmpl.tissue.GEL_TRUSTED_COMPRESSION`):
    a point load that moves the skin in under it is an answer, one that moves it further is
    failed as not trusted, with the bound named; a solver whose own limit is looser changes
    nothing.
    """
    part = sheet(0.1, 0.1, 9, 9)
    mesh = shell_mesh(part, np.full(part.n_vertices, 0.01), layers=2)
    force = np.zeros(part.n_vertices)
    force[40] = 0.1
    ok = Solver(mesh).solve(force)
    assert ok.ok and 0 < ok.max_compression < GEL_TRUSTED_COMPRESSION
    for f in (0.2, 0.4, 0.8):
        s = Solver(mesh).solve(force * f / 0.1)
        if not s.ok:
            break
    assert not s.ok and s.reason.startswith("not trusted: the skin moves inward")
    assert f"trusted up to {GEL_TRUSTED_COMPRESSION:g}" in s.reason and "gel" in s.reason


def test_a_tissue_s_trust_bounds_reject_an_answer_past_them():
    """A layered tissue's :class:`Limits` are checked on every answer: the same solve is
    trusted under loose bounds and failed with its reason when the volume ratio or the
    compression it reaches lies past them.
    """
    part = sheet(0.1, 0.1, 9, 9)
    mesh = shell_mesh(part, np.full(part.n_vertices, 0.01), layers=2)
    force = np.zeros(part.n_vertices)
    force[40] = 0.1
    laws = (NeoHookean(), NeoHookean())
    loose = _layered(mesh, laws)
    ok = Solver(mesh, loose).solve(force)
    assert ok.ok and 0 < ok.min_det_F < 1 and 0 < ok.max_compression < 1
    for limits, words in [
        (Limits(0.5 * (1 + ok.min_det_F), 1.0, "squeeze", "volume"), "keeps"),
        (Limits(0.0, 0.5 * ok.max_compression, "squeeze", "volume"), "moves inward"),
    ]:
        bad = Solver(mesh, replace(loose, limits=limits)).solve(force)
        assert not bad.ok and bad.displacement is None
        assert bad.reason.startswith("not trusted") and words in bad.reason
        # each bound names its own source
        assert ("volume" in bad.reason) == (words == "keeps")
        assert ("squeeze" in bad.reason) == (words == "moves inward")
    with pytest.raises(ValueError, match="min_det_F in"):
        Limits(1.2, 0.5)
    with pytest.raises(ValueError, match="max_compression in"):
        Limits(0.5, 0.0)


def test_bad_input_is_named():
    part, mesh = _small_shell(layers=1)
    with pytest.raises(ValueError, match="mean dilatation needs laws with a bulk modulus"):
        Solver(mesh, NeoHookean(), options=SolverOptions(volume="mean"))
    with pytest.raises(ValueError, match="volume must be"):
        SolverOptions(volume="average")
    part, mesh = _small_shell()
    S = Solver(mesh)
    with pytest.raises(ValueError, match="force must have shape"):
        S.solve(np.zeros(3))
    bad = np.zeros(part.n_vertices)
    bad[0] = np.nan
    with pytest.raises(ValueError, match="finite"):
        S.solve(bad)
    with pytest.raises(ValueError, match="fixed must have shape"):
        Solver(mesh, fixed=np.zeros((2, 3), bool))
    with pytest.raises(ValueError, match="linear_solver"):
        SolverOptions(linear_solver="magic")
    with pytest.raises(ValueError, match="no force"):
        S.continuation(np.zeros(part.n_vertices), [1.0])


def test_compiled_and_numpy_assembly_agree(monkeypatch):
    """The Numba kernel against the NumPy path (numba is a dependency: without it this test
    would compare NumPy with NumPy, so it fails instead).
    """
    assert fs.compiled() is not None, "numba is missing: the compiled kernel cannot be checked"
    part, mesh = _small_shell(layers=1)
    rng = np.random.default_rng(3)
    cases = [("superlu", 1, None), ("pardiso", 1, None), ("superlu", 2, None)]
    cases += [("superlu", 1, "layered"), ("pardiso", 2, "layered"), ("pardiso", 2, "tissue")]
    cases += [("superlu", 2, "tissue")]
    for name, order, material in cases:
        if name not in available_linear_solvers():
            continue
        volume = "mean" if material == "tissue" else "auto"  # the tissue: mean dilatation
        if material:
            laws = (YEOH, DEMIRAY) if material == "tissue" else (NeoHookean(), DEMIRAY)
            material = _layered(mesh, laws)
        options = SolverOptions(linear_solver=name, volume=volume)
        S = Solver(mesh, material, options=options, order=order)
        u = np.zeros((S.n_all, 3))
        u.reshape(-1)[S.free] = rng.normal(0, 5e-4, len(S.free))
        for definite in (False, True):
            K1 = S.assemble(u, u, definite)[1]
            monkeypatch.setattr(fs, "compiled", lambda: None)
            K2 = S.assemble(u, u, definite)[1]
            monkeypatch.undo()
            assert abs(K1 - K2).max() <= 1e-12 * abs(K2).max()


def test_auto_falls_back_to_superlu_without_pardiso(monkeypatch):
    import fem.linear_solvers as fs

    def missing():
        raise ImportError("no MKL here")

    monkeypatch.setitem(fs.LINEAR_SOLVERS, "pardiso", missing)
    monkeypatch.setitem(fs.LINEAR_SOLVERS, "pardiso_single", missing)
    with pytest.warns(RuntimeWarning, match="SuperLU"):
        solver = fs.make_linear_solver("auto")
    assert solver.name == "superlu"
    with pytest.raises(ImportError, match="not installed"):
        fs.make_linear_solver("pardiso")


@pytest.mark.parametrize("law", [NeoHookean(1000.0, 0.45), YEOH, DEMIRAY], ids=lambda m: m.name)
@pytest.mark.parametrize("order", [1, 2])
def test_uniaxial_compression_follows_each_laws_exact_curve(law, order):
    """A slab sliding on a rigid base, free sides, under a uniform dead pressure on top: the
    FEM's stretch at each pressure lies within 0.5 % of the law's exact homogeneous curve,
    down to 30 % compression.
    """
    h = 0.01
    part = sheet(0.04, 0.04, 5, 5)
    mesh = shell_mesh(part, np.full(part.n_vertices, h), layers=2, normal_smoothing=0)
    fixed = np.zeros((mesh.n_nodes, 3), bool)
    inner = mesh.inner_nodes
    fixed[inner, 2] = True  # the base: sliding, frictionless
    corner = inner[np.argmin(np.linalg.norm(mesh.nodes[inner, :2] + 0.02, axis=1))]
    fixed[corner, :2] = True  # no rigid sliding or spin
    across = inner[np.argmin(np.linalg.norm(mesh.nodes[inner, :2] - [0.02, -0.02], axis=1))]
    fixed[across, 1] = True
    S = Solver(mesh, law, fixed, SolverOptions(rims="free"), order=order, hold_inner=False)
    stretches = [0.9, 0.8, 0.7]
    pressures = [-uniaxial(law, s)[0] for s in stretches]
    pattern = part.vertex_areas  # N per Pa of pressure on each vertex
    sols = S.continuation(pattern, [p * pattern.sum() for p in pressures])
    for s, sol in zip(stretches, sols):
        assert sol.ok, sol.reason
        top = sol.displacement[: part.n_vertices, 2]
        measured = 1 + top.mean() / h
        assert measured == pytest.approx(s, rel=0.005)
        assert np.ptp(top) < 1e-6 * h  # homogeneous


def test_a_kept_factorisation_preconditions_the_next_solve():
    """A solve warm-started from a neighbour's answer solves its Newton steps by CG on the
    current tangent with the neighbour's factorisation: no new factorisation, and the answer
    of plain Newton (a factorisation every step) within the solves' tolerance.
    """
    part, mesh = _small_shell()
    force = np.zeros(part.n_vertices)
    force[20:23] = 0.05
    solver = Solver(mesh)
    rest = np.zeros((solver.n_all, 3))
    first = solver.equilibrium(rest, solver.external_forces(0.8 * force))
    second = solver.equilibrium(first["u"], solver.external_forces(force))
    assert first["ok"] and second["ok"]
    assert first["factorisations"] >= 1 and second["factorisations"] == 0
    plain = Solver(mesh, options=SolverOptions(reuse=0))
    ref = plain.equilibrium(rest, plain.external_forces(force))
    assert ref["factorisations"] >= second["iterations"]
    np.testing.assert_allclose(second["u"], ref["u"], atol=1e-6 * np.abs(ref["u"]).max())


def test_a_solver_and_its_factorisation_go_with_its_last_reference():
    """No reference cycle holds a solver (its tangent keeps its assembly as a weak method): its
    factorisation (PARDISO's memory, outside Python's view) is freed when the solver goes, not
    when the cycle collector next runs; and the tangent still assembles while the solver lives.
    """
    import gc
    import weakref

    part, mesh = _small_shell(layers=1)
    S = Solver(mesh, NeoHookean(), options=SolverOptions(linear_solver="superlu"))
    u = np.zeros((mesh.n_nodes, 3))
    r, K = S.tangent.assemble(u, np.zeros_like(u), False)
    assert (
        K.shape == (len(S.free), len(S.free)) and S.tangent.factorise(u, np.zeros_like(u)) is None
    )
    gone = weakref.ref(S)
    was = gc.isenabled()
    gc.disable()
    try:
        del S
        assert gone() is None
    finally:
        if was:
            gc.enable()
