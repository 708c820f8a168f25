"""Shaded 3D pictures (stmpl/viz/render.py)."""

import numpy as np
import pytest

from stmpl.body.primitives import sheet, tube
from stmpl.viz.render import contact_figure, refine, skin_faces


def test_refine_keeps_area_and_interpolates_linearly():
    tri = np.array([[[0.0, 0, 0], [1, 0, 0], [0, 1, 0]]])
    vals = tri[..., 0] + 2 * tri[..., 1]  # a linear field
    t, v = refine(tri, vals, levels=2)
    assert t.shape == (16, 3, 3) and v.shape == (16, 3)
    area = 0.5 * np.linalg.norm(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]), axis=1)
    assert area.sum() == pytest.approx(0.5)
    np.testing.assert_allclose(v, t[..., 0] + 2 * t[..., 1])


def test_pictures_leave_out_the_faces_that_span_a_cut():
    """A face whose three corners lie on an open rim spans the cut (on a sheet: the two
    corner triangles), not the skin; a closed tube's rim faces each keep a corner inside.
    """
    flat = sheet(0.1, 0.1, 5, 5)
    kept = skin_faces(flat)
    rim = np.zeros(flat.n_vertices, bool)
    rim[np.concatenate(flat.rims)] = True
    assert len(kept) == len(flat.faces) - 2 and not rim[kept].all(1).any()
    limb = tube()
    np.testing.assert_array_equal(skin_faces(limb), limb.faces)


def test_contact_figure(tmp_path, arm):
    import stmpl.contact.pressing as contact
    from stmpl import Scene, tissue
    from stmpl.contact import objects
    from stmpl.pipeline import zoo

    bar = objects.rod(0.01, 0.08)
    touch = contact.contact(
        arm, contact.Pressing(bar, objects.press(arm, bar, uv=(0.45, 0.5), depth=0.004), 0.3, "bar")
    )
    scene = Scene.from_load(arm, tissue.constant(arm, 0.0075), touch.load())
    d = zoo.read("linear_arm").predict(scene)
    fig = contact_figure({"linear": d}, None, [touch.objects[0].posed()], tmp_path / "c.png")
    assert (tmp_path / "c.png").stat().st_size > 30_000
    assert "bar 0.3 N" in fig._suptitle.get_text()
    title = fig.axes[0].get_title()
    assert "outside its envelope" not in title
    # an answer outside the model's envelope says so in its panel, in red
    d.info["envelope"] = {
        "inside": False,
        "outside": ["mean pressure of a contact 0.48 kPa > 0.4 kPa (where it was measured)"],
    }
    fig = contact_figure({"linear": d}, None, [touch.objects[0].posed()], tmp_path / "c.png")
    ax = fig.axes[0]
    assert " ".join(ax.get_title().split()).endswith(
        "outside its envelope: mean pressure of a contact 0.48 kPa > 0.4 kPa"
    )
    assert ax.title.get_color() == "#a00000"
    # a long reason is cut to its claim and wrapped to the panel's width
    d.info["envelope"]["outside"] = [
        "no scene in the data combines its thickness, force, area and pressures: the nearest "
        "lies 1.54 x the data's spacing away"
    ]
    fig = contact_figure({"linear": d}, None, [], tmp_path / "c.png")
    title = fig.axes[0].get_title()
    assert " ".join(title.split()).endswith("combines its thickness, force, area and pressures")
    assert max(len(line) for line in title.splitlines()) <= 46
    d.info["physical"] = False  # an answer saved before the reasons were kept
    fig = contact_figure({"linear": d}, None, [], tmp_path / "c.png")
    title = " ".join(fig.axes[0].get_title().split())
    assert title.endswith("thickness, past 0.4, where the gel buckles: do not use"), title
    d.info["impossible"] = ["the object pulls on the skin (-0.2 N)"]
    fig = contact_figure({"linear": d}, None, [], tmp_path / "c.png")
    title = " ".join(fig.axes[0].get_title().split())
    assert title.endswith("the object pulls on the skin (-0.2 N): do not use"), title
    with pytest.raises(ValueError, match="no deformations"):
        contact_figure({})


def test_titles_name_the_body_s_phenotype(arm):
    from dataclasses import replace

    from stmpl.viz.render import body_words

    phenotype = {"gender": 0.5, "weight": 0.7, "muscle": 0.3}
    heavy = replace(arm, source={"body": "anny", "options": {"phenotype": phenotype}})
    assert body_words(heavy) == " of anny (weight 0.7, muscle 0.3)"
    plain = replace(arm, source={"body": "anny", "options": {"phenotype": {"weight": 0.5}}})
    assert body_words(plain) == " of anny (default body)"
    assert body_words(replace(arm, source={})) == ""


def test_a_title_says_an_object_was_pressed_on_until_it_met_a_force():
    """A posed scene's title says the force is answered; the same scene reached by force
    control says how far the object was pressed on and to what force.
    """
    from stmpl import tissue
    from stmpl.body import tube
    from stmpl.contact import objects
    from stmpl.contact.posing import posed
    from stmpl.viz.render import _title

    part = tube(n_around=16, n_along=11)
    tip = objects.sphere(0.008)
    scene = posed(part, tissue.constant(part, 0.0075), tip, objects.press(part, tip, uv=(0.5, 0.5)))
    assert _title(scene).endswith("the force is answered")
    forced = " ".join(_title(scene, {"moved_mm": 4.613, "force": 5.0}).split())
    assert forced.endswith("object pressed on 4.61 mm from where it was put, until it meets 5 N")


def test_answers_with_a_contact_pressure_get_a_row_of_it():
    """A posed scene's answers: below each dent its contact pressure on the skin (kPa, one
    scale), a failed solve's panel saying it has no answer; a scene given by force: one row.
    """
    from stmpl.scene import Deformation
    from tests.conftest import pressed_ball

    scene = pressed_ball(tube())
    inside = np.clip(-scene.pose.gap, 0, None)
    area = scene.part.vertex_areas
    u = -scene.part.normals * inside[:, None]
    fem = Deformation(scene, u, {"seconds": 30.0}, 2e3 * inside / inside.max() * area, 0.9)
    model = Deformation(scene, 0.9 * u, {"seconds": 0.004}, 0.5 * fem.force, 0.45)
    fig = contact_figure({"gnn": model}, fem, [], failed={"FEM (fine)": "did not converge"})
    titles = [ax.get_title() for ax in fig.axes]
    assert titles[3:6] == [
        "no answer",
        "contact pressure, peak 2 kPa",
        "contact pressure, peak 1 kPa",
    ], titles
    assert [ax.get_ylabel() for ax in fig.axes[6:]] == [
        "displacement |u| (mm)",
        "contact pressure (kPa)",
    ]
    pressed_row = fig.axes[3].get_position()
    assert pressed_row.y1 < fig.axes[0].get_position().y0  # below the dents
    from stmpl import loads
    from stmpl.scene import Scene

    part = scene.part
    by_force = Scene(part, scene.thickness, loads.disk(part, 5, 0.02, 0.1).force)
    flat = Deformation(by_force, u, {"seconds": 0.001})
    assert len(contact_figure({"linear": flat}).axes) == 2  # one panel and its bar
