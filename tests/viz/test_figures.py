import numpy as np
import pytest
import trimesh

import stmpl.viz.figures as viz
from stmpl import loads, tissue
from stmpl.scene import Scene


def test_scene_picture(arm, tmp_path):
    import matplotlib.image as mpimg

    s = Scene.from_load(arm, tissue.ramp(arm, 0.005, 0.01), loads.seam_disk(arm, 0.5, 0.03, 5))
    viz.scene_figure(s, tmp_path / "s.png")
    img = mpimg.imread(tmp_path / "s.png")
    assert img.shape[0] > 500 and img.shape[1] > 1000
    # the force colour map's bright end appears (the load is drawn), and so does the background
    assert (img[..., :3].std(axis=2) > 0.2).mean() > 0.005


def test_view_faces_the_load(arm):
    ld = loads.disk(arm, uv=(0.5, 0.5), radius=0.03, total=1)
    basis = viz.view_basis(arm, ld.force)
    assert (arm.normals[ld.vertices] @ basis[2]).mean() > 0.7


@pytest.mark.parametrize("suffix", [".ply", ".obj", ".glb"])
def test_mesh_export_with_colours(arm, tmp_path, suffix):
    values = arm.vertices[:, 0]
    path = viz.export_mesh(arm, tmp_path / f"m{suffix}", values)
    m = trimesh.load(path, force="mesh", process=False)
    assert len(m.faces) == arm.n_faces
    assert len(np.unique(m.visual.vertex_colors[:, :3], axis=0)) > 50


def test_export_rejects_bad_input(arm, tmp_path):
    with pytest.raises(ValueError, match="supports .ply"):
        viz.export_mesh(arm, tmp_path / "m.stl")
    with pytest.raises(ValueError, match="values must have shape"):
        viz.export_mesh(arm, tmp_path / "m.ply", np.zeros(3))


def test_section_of_a_flat_layer_has_the_layer_area():
    from fem.mesh import shell_mesh
    from fem.pictures import section
    from stmpl.body.primitives import sheet

    part = sheet(0.1, 0.1, 8, 8)
    mesh = shell_mesh(part, np.full(part.n_vertices, 0.006), layers=2)
    polys, vals = section(
        mesh.nodes,
        mesh.tets,
        np.array([0.013, 0.0, 0.0]),
        np.array([1.0, 0.0, 0.0]),
        values=mesh.nodes[:, 1],
    )

    def area(p):
        c = p - p.mean(0)
        return 0.5 * abs(sum(np.cross(c[i], c[(i + 1) % len(c)])[0] for i in range(len(c))))

    assert sum(area(p) for p in polys) == pytest.approx(0.1 * 0.006, rel=1e-9)
    assert np.all(np.abs(vals) <= 0.05 + 1e-12)


@pytest.mark.parametrize("shared", [False, True])
def test_prediction_figure_error_scales(arm, shared):
    """Each error panel has its own colour scale (up to that row's largest error, mm), or with
    ``shared_error_scale`` one scale for all rows.
    """
    from stmpl.scene import Deformation

    s = Scene.from_load(
        arm, tissue.constant(arm, 0.0075), loads.disk(arm, uv=(0.5, 0.5), radius=0.02, total=0.3)
    )
    u = np.zeros((arm.n_vertices, 3))
    u[s.force > 0] = [0.0, 0.0, 1e-3]
    truth = Deformation(s, u)
    good, poor = Deformation(s, 1.01 * u), Deformation(s, 1.5 * u)
    fig = viz.prediction_figure(
        {"good": good, "poor": poor}, truth, shared_error_scale=shared, size=64
    )
    axes = np.asarray(fig.axes).reshape(-1)
    tops = [a.images[0].get_clim()[1] for a in axes if a.images and "error" in a.get_title()]
    assert tops == pytest.approx([0.5, 0.5] if shared else [0.01, 0.5], rel=1e-6)
