import numpy as np
import pytest

from fem.mesh import check_surface, midpoint_subdivide, shell_mesh, tet_volumes
from stmpl.body.primitives import sheet, tube


def _closed_tube(n_around=32, radius=0.05, length=0.1):
    return tube(radius=radius, length=length, n_around=n_around, n_along=6)


def test_tube_shell_volume_layers_and_numbering():
    part = _closed_tube()
    t = 0.01
    m = shell_mesh(part, np.full(part.n_vertices, t), layers=3, normal_smoothing=0)
    S = part.n_vertices
    assert m.n_skin == S and m.n_nodes == 4 * S and len(m.tets) == 3 * 3 * part.n_faces
    np.testing.assert_array_equal(m.part_nodes, np.arange(S))
    # inner nodes sit at radius - t (tube normals are radial, smoothing keeps them radial)
    r_in = np.linalg.norm(m.nodes[m.inner_nodes][:, :2], axis=1)
    np.testing.assert_allclose(r_in, 0.05 - t, rtol=1e-9)
    # shell volume: a 32-gon annulus prism
    n = 32
    area = 0.5 * n * np.sin(2 * np.pi / n) * (0.05**2 - 0.04**2)
    assert m.volumes.sum() == pytest.approx(area * 0.1, rel=1e-9)
    q = m.quality()
    assert q.n_inverted == 0 and q.min_volume > 0 and 0 < q.min_dihedral < q.max_dihedral < 180


def test_subdivision_keeps_surface_and_interpolates_linearly():
    part = _closed_tube(12)
    x, f, P = midpoint_subdivide(part.vertices, part.faces)
    assert len(f) == 4 * part.n_faces
    check_surface(x, f)  # still manifold and consistently oriented

    def area(x, f):
        v = x[f]
        return 0.5 * np.linalg.norm(np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]), axis=1).sum()

    assert area(x, f) == pytest.approx(area(part.vertices, part.faces), rel=1e-12)
    lin = part.vertices @ np.array([1.0, -2.0, 0.5])
    np.testing.assert_allclose(P @ lin, x @ np.array([1.0, -2.0, 0.5]), atol=1e-14)


def test_local_refinement_is_conforming_and_local():
    part = sheet(0.2, 0.2, 11, 11)
    marked = np.linalg.norm(part.vertices[part.faces].mean(1), axis=1) < 0.03
    x, f, P = midpoint_subdivide(part.vertices, part.faces, marked)
    check_surface(x, f)  # no hanging nodes: every edge has at most two faces, orientation kept

    # boundary of the sheet is untouched: same boundary-edge length
    def boundary_len(x, f):
        e = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), 1)
        u, c = np.unique(e, axis=0, return_counts=True)
        b = u[c == 1]
        return np.linalg.norm(x[b[:, 0]] - x[b[:, 1]], axis=1).sum(), len(b)

    assert boundary_len(x, f) == pytest.approx(boundary_len(part.vertices, part.faces))
    assert part.n_faces < len(f) < 2 * part.n_faces
    # a hanging node would leave a T-junction: every new node lies on >= 4 faces
    deg = np.bincount(f.ravel(), minlength=len(x))
    assert deg[part.n_vertices :].min() >= 4


def test_refine_near_load_and_shell_quality():
    part = _closed_tube(24)
    near = part.vertices[:1]
    m = shell_mesh(
        part,
        np.full(part.n_vertices, 0.008),
        layers=2,
        subdivisions=2,
        refine_near=near,
        refine_radius=0.02,
    )
    full = shell_mesh(part, np.full(part.n_vertices, 0.008), layers=2, subdivisions=2)
    assert m.n_nodes < full.n_nodes / 2
    coarse = shell_mesh(part, np.full(part.n_vertices, 0.008), layers=2)
    assert m.quality().n_inverted == 0
    # midpoints are offset along interpolated normals, so refined faces bulge a little inward
    vol = tet_volumes(m.nodes, m.tets).sum()
    assert coarse.volumes.sum() < vol < full.volumes.sum() < 1.01 * coarse.volumes.sum()


@pytest.mark.parametrize("mode", ["traction", "nodal"])
def test_nodal_forces_keep_the_total(mode):
    part = _closed_tube(24)
    force = np.zeros(part.n_vertices)
    force[[30, 31, 55]] = [0.5, 0.25, 1.0]
    for s in (0, 1, 2):
        m = shell_mesh(
            part,
            np.full(part.n_vertices, 0.008),
            layers=1,
            subdivisions=s if mode == "traction" else 0,
        )
        f = m.nodal_forces(force, mode)
        assert np.linalg.norm(f, axis=1).sum() == pytest.approx(1.75, rel=1e-12)
        # all along the inward normal (radial on a tube), so nothing on fixed nodes
        assert np.all(np.einsum("si,si->s", f[: m.n_skin], m.skin_normals) <= 1e-15)
        assert np.abs(f[m.n_skin :]).max() == 0


def test_constant_pressure_on_a_sheet_gives_p_times_area():
    part = sheet(0.1, 0.1, 6, 6)
    m = shell_mesh(part, np.full(part.n_vertices, 0.005), layers=1, subdivisions=1)
    p = 50.0
    f = m.nodal_forces(p * part.vertex_areas)
    np.testing.assert_allclose(-f[: m.n_skin, 2], p * m.skin_areas, rtol=1e-12)


def test_vtu_export_round_trip(tmp_path):
    meshio = pytest.importorskip("meshio")
    part = _closed_tube(8)
    m = shell_mesh(part, np.full(part.n_vertices, 0.01), layers=1)
    u = np.random.default_rng(0).normal(size=(m.n_nodes, 3))
    path = m.to_vtu(tmp_path / "shell.vtu", point_data={"displacement": u})
    back = meshio.read(path)
    np.testing.assert_allclose(back.points, m.nodes)
    np.testing.assert_array_equal(back.cells_dict["tetra"], m.tets)
    np.testing.assert_allclose(back.point_data["displacement"], u)
    with pytest.raises(ValueError, match="point data"):
        m.to_vtu(tmp_path / "x.vtu", point_data={"bad": u[:3]})


def test_bad_input_is_named():
    part = _closed_tube(16)
    n = part.n_vertices
    with pytest.raises(ValueError, match="thickness must have shape"):
        shell_mesh(part, np.full(n - 1, 0.01))
    bad = np.full(n, 0.01)
    bad[7] = np.nan
    with pytest.raises(ValueError, match="vertex 7"):
        shell_mesh(part, bad)
    with pytest.raises(ValueError, match="folds the inner surface"):
        shell_mesh(part, np.full(n, 0.06))  # thicker than the 5 cm radius
    with pytest.raises(ValueError, match="layers"):
        shell_mesh(part, np.full(n, 0.01), layers=0)
    # degenerate face
    v = part.vertices.copy()
    f = part.faces.copy()
    f[0] = [f[0, 0], f[0, 0], f[0, 1]]
    with pytest.raises(ValueError, match="degenerate"):
        check_surface(v, f)
    # non-manifold edge: a third face on an interior edge
    a, b = part.faces[40, :2]
    f2 = np.concatenate([part.faces, [[b, a, n - 1]]])
    with pytest.raises(ValueError, match="non-manifold"):
        check_surface(v, f2)
    flipped = part.faces.copy()
    flipped[0] = flipped[0, ::-1]
    with pytest.raises(ValueError, match="oriented"):
        check_surface(v, flipped)
    with pytest.raises(ValueError, match="load mode"):
        shell_mesh(part, np.full(n, 0.01)).nodal_forces(np.zeros(n), "magic")
