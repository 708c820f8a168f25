"""Tissue presets: the layers' thicknesses from the scene and the phenotype, their meshing and
their laws, element by element.
"""

import numpy as np
import pytest

from fem.contact import press
from fem.layers import MIN_FAT, MIN_MUSCLE, PRESETS, TRUSTED, bound, preset
from fem.mesh import shell_mesh
from fem.predictor import FEMPredictor
from fem.shapes import Sphere
from fem.simulate import tissue_mesh
from fem.solver import Solver
from stmpl import tissue
from stmpl.body.primitives import sheet, tube


def test_the_scene_thickness_is_skin_and_fat_and_the_muscle_lies_under_it():
    forearm = PRESETS["forearm"]
    t = np.array([0.005, 0.0075, 0.01])
    skin, fat, muscle = forearm.thicknesses(t, {"gender": 0.5, "age": 0.2, "muscle": 0.5})
    np.testing.assert_allclose(skin + fat, t)
    np.testing.assert_allclose(skin, 0.0012 * 1.0 * (1.05 - 0.05))
    np.testing.assert_allclose(muscle, 0.010)
    men, women = (forearm.thicknesses(t, {"gender": g})[0, 0] for g in (1.0, 0.0))
    assert men / women == pytest.approx(1.05 / 0.95)
    young, old = (forearm.thicknesses(t, {"age": a})[0, 0] for a in (0.0, 1.0))
    assert old < 0.8 * young
    strong = forearm.thicknesses(t, {"muscle": 1.0})[2, 0]
    assert strong == pytest.approx(0.012)


def test_a_thin_limb_thins_the_muscle_and_too_thin_a_scene_is_refused():
    arm = PRESETS["upper_arm"]
    t = np.full(3, 0.006)
    layers = arm.thicknesses(t, room=np.array([0.03, 0.012, 0.001]))
    np.testing.assert_allclose(layers[2], [0.015, 0.006, MIN_MUSCLE])
    with pytest.raises(ValueError, match="leaves no room for skin and fat"):
        arm.thicknesses(np.full(3, 0.0012 + MIN_FAT / 2), {"gender": 1.0})
    with pytest.raises(ValueError, match="unknown tissue preset 'gel'"):
        preset("gel")
    with pytest.raises(ValueError, match="phenotype age must be in"):
        arm.thicknesses(t, {"age": 1.5})
    assert preset("paper") is None


def test_each_layer_is_meshed_through_its_own_depth_with_its_own_law():
    part = sheet(0.04, 0.04, 5, 5)
    forearm = PRESETS["forearm"]
    layers = forearm.thicknesses(np.full(part.n_vertices, 0.008))
    frac = forearm.fractions(layers)
    assert frac.shape == (forearm.elements + 1, part.n_vertices)
    mesh = shell_mesh(part, layers.sum(0), forearm.elements, normal_smoothing=0, fractions=frac)
    depth = -mesh.nodes[:, 2].reshape(forearm.elements + 1, -1)[:, 0]  # a column of nodes
    interfaces = np.cumsum(layers[:, 0])
    assert depth[1] == pytest.approx(interfaces[0])  # the skin: one element
    assert depth[3] == pytest.approx(interfaces[1])  # the fat: two
    assert depth[-1] == pytest.approx(interfaces[2])
    mat = forearm.material(mesh.tet_layers)
    centroid = -mesh.nodes[mesh.tets].mean(1)[:, 2]
    law = np.asarray(mat.layer)
    assert np.all((centroid < interfaces[0]) == (law == 0))
    assert np.all((centroid > interfaces[1]) == (law == 2))


def test_the_fem_meshes_a_preset_on_a_curved_part():
    part = tube(radius=0.04, length=0.1, n_around=16, n_along=6)
    t = np.full(part.n_vertices, 0.0075)
    mesh, mat = tissue_mesh(part, t, "medium", tissue="forearm")
    assert mesh.layers == PRESETS["forearm"].elements
    assert mesh.thickness.max() == pytest.approx(0.0175, rel=1e-6)
    assert mat.name == "layered" and len(mat.laws) == 3 and len(mat.layer) == len(mesh.tets)
    assert mat.limits == TRUSTED and 0 < TRUSTED.min_det_F < 1 and 0 < TRUSTED.max_compression < 1
    gel, none = tissue_mesh(part, t, "coarse")
    assert none is None and gel.thickness.max() == pytest.approx(0.0075)
    with pytest.raises(ValueError, match="lock in linear"):  # linear elements lock in it
        tissue_mesh(part, t, "coarse", tissue="forearm")


def test_a_fingertip_on_the_layered_forearm_stiffens_into_newtons():
    """A rigid 8 mm sphere pushed into the forearm preset on an arm-sized tube: the reaction
    grows convexly with depth (the fat stiffens) to newtons at 6 mm, while the paper's gel,
    which creases past about half its thickness, carries a few hundredths of a newton at 2 mm.
    """
    part = tube(radius=0.035, length=0.08, n_around=24, n_along=8)
    t = np.full(part.n_vertices, 0.0075)
    top = int(np.argmax(part.vertices[:, 0] - 10 * np.abs(part.vertices[:, 2] - 0.04)))
    p, n = part.vertices[top], part.normals[top]
    force = {}
    for name, depths in (("forearm", [0.002, 0.004, 0.006]), ("paper", [0.002])):
        mesh, mat = tissue_mesh(part, t, "medium", tissue=name, near=p[None])
        solver = Solver(mesh, mat, order=2)
        out = press(solver, Sphere(p + 0.008 * n, 0.008), -n, depths)
        assert all(r.ok for r in out), [r.reason for r in out]
        force[name] = np.array([r.reaction for r in out])
    f = force["forearm"]
    assert f[-1] > 1.0 and f[1] - f[0] < f[2] - f[1]  # newtons, and convex
    assert force["paper"][0] < 0.2 * f[0]


def test_a_tissue_file_overrides_a_preset_layer_by_layer(tmp_path):
    """A YAML file of layers: what it gives replaces the preset's (the skin's law and base
    thickness here), the rest is the preset's; without ``based_on`` every part is needed.
    """
    path = tmp_path / "firm.yaml"
    path.write_text(
        "name: firm_forearm\nbased_on: forearm\nskin_mm: 1.5\n"
        "layers:\n  skin: {law: yeoh, C10: 300000, C20: 1000, K: 8.0e6, elements: 2}\n"
    )
    firm = preset(str(path))
    assert firm.name == "firm_forearm" and firm.skin == pytest.approx(0.0015)
    assert firm.muscle == PRESETS["forearm"].muscle
    skin = firm.layers[0]
    assert (skin.law.C10, skin.law.C20, skin.law.K, skin.elements) == (3e5, 1e3, 8e6, 2)
    assert firm.layers[1:] == PRESETS["forearm"].layers[1:]
    assert firm.limits == TRUSTED  # a file's layered tissue is trusted as far as the presets
    t = firm.thicknesses(np.full(3, 0.0075), {"gender": 0.5, "age": 0.2})
    np.testing.assert_allclose(t[0], 0.0015 * 1.0 * (1.05 - 0.05))
    whole = {
        "name": "gel_on_muscle",
        "skin_mm": 1.0,
        "muscle_mm": 5,
        "layers": {
            "skin": {"law": "neo_hookean", "E": 9e5, "nu": 0.49},
            "fat": {"law": "demiray", "a": 500.0, "b": 5.0, "K": 3e4},
            "muscle": {"law": "yeoh", "C10": 1200.0, "K": 1.2e5},
        },
    }
    assert [x.law.name for x in preset(whole).layers] == ["neo_hookean", "demiray", "yeoh"]


@pytest.mark.parametrize(
    "spec, message",
    [
        ({"name": "x", "based_on": "forearm", "colour": 1}, "unknown keys \\['colour'\\]"),
        ({"name": "forearm", "based_on": "forearm"}, "name must be a new"),
        ({"name": "x", "based_on": "leg"}, "based_on must be one of"),
        (
            {"name": "x", "skin_mm": 1},
            "without based_on, give \\['fat', 'muscle', 'muscle_mm', 'skin'\\]",
        ),
        ({"name": "x", "based_on": "forearm", "skin_mm": -1}, "skin_mm must be a length"),
        (
            {"name": "x", "based_on": "forearm", "layers": {"bone": {"law": "yeoh"}}},
            "layers must be a mapping of",
        ),
        (
            {"name": "x", "based_on": "forearm", "layers": {"fat": {"law": "ogden"}}},
            "fat: unknown law 'ogden'",
        ),
        (
            {"name": "x", "based_on": "forearm", "layers": {"fat": {"law": "yeoh", "mu": 1.0}}},
            "fat: yeoh takes other parameters",
        ),
        (
            {"name": "x", "based_on": "forearm", "layers": {"fat": {"law": "yeoh", "C10": -1}}},
            "fat: yeoh: C10",
        ),
        (
            {"name": "x", "based_on": "forearm", "layers": {"fat": {"law": "yeoh", "C10": "a"}}},
            "C10 must be a number",
        ),
    ],
)
def test_a_bad_tissue_file_is_named(spec, message):
    with pytest.raises(ValueError, match=message):
        preset(spec)


def test_a_missing_or_broken_tissue_file_is_named(tmp_path):
    with pytest.raises(ValueError, match="does not exist"):
        preset(str(tmp_path / "none.yaml"))
    (tmp_path / "bad.yaml").write_text("name: [\n")
    with pytest.raises(ValueError, match="is not YAML"):
        preset(str(tmp_path / "bad.yaml"))
    (tmp_path / "list.yaml").write_text("- 1\n")
    with pytest.raises(ValueError, match="must hold a mapping"):
        preset(str(tmp_path / "list.yaml"))
    with pytest.raises(ValueError, match="unknown tissue preset 'leg'"):
        preset("leg")


def test_a_layered_tissue_s_bound_counts_its_deepest_muscle_under_the_skin_and_fat():
    """An answer is impossible past the trusted compression of the whole depth; the bound counts
    the muscle at its deepest over anny's phenotypes (so no answer the FEM could give is past
    it), and the gel keeps its own (0.4 of its thickness). The FEM predictor and the layers
    agree.
    """
    assert bound("paper") == tissue.GEL
    t = np.full(5, 0.0075)
    for name, p in PRESETS.items():
        b = bound(name)
        deepest = max(p.thicknesses(t, {"muscle": m})[2].max() for m in (0.0, 0.5, 1.0))
        assert b.compression == TRUSTED.max_compression and b.below == pytest.approx(deepest)
        assert f"up to {1e3 * deepest:.0f} mm of muscle" in b.depth
    assert FEMPredictor(tissue="abdomen", res="medium").bound == bound("abdomen")
