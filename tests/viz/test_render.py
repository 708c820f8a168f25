"""Shaded 3D pictures (stmpl/viz/render.py)."""

import numpy as np
import pytest

from stmpl.body.primitives import sheet, tube
from stmpl.viz.colours import ramp
from stmpl.viz.render import contact_figure, skin_faces


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
    assert "bar 0.3 N" in fig.title
    title = fig.panels[0].title
    assert "outside its envelope" not in title and fig.panels[0].colour == "black"
    # the panel shows the skin, lit, and its dent in the ramp's reds; the bar runs its ramp
    x0, y0, x1, y1 = fig.panels[0].box
    px = np.asarray(fig.image)[y0:y1, x0:x1].astype(int)
    drawn = (px < 250).any(2)
    assert 0.2 < drawn.mean() < 0.95
    assert ((px[..., 0] - px[..., 2] > 120) & (px[..., 1] < 120)).sum() > 20  # the deepest
    ((label, (bx0, by0, bx1, by1)),) = fig.bars
    assert label == "displacement |u| (mm)"
    bar = np.asarray(fig.image)[by0 + 2 : by1 - 1, (bx0 + bx1) // 2] / 255
    np.testing.assert_allclose(bar[0], ramp("YlOrRd", 1.0), atol=0.02)
    np.testing.assert_allclose(bar[-1], ramp("YlOrRd", 0.0), atol=0.02)
    # an answer outside the model's envelope says so in its panel, in red
    d.info["envelope"] = {
        "inside": False,
        "outside": ["mean pressure of a contact 0.48 kPa > 0.4 kPa (where it was measured)"],
    }
    fig = contact_figure({"linear": d}, None, [touch.objects[0].posed()], tmp_path / "c.png")
    panel = fig.panels[0]
    assert " ".join(panel.title.split()).endswith(
        "outside its envelope: mean pressure of a contact 0.48 kPa > 0.4 kPa"
    )
    assert panel.colour == "#a00000"
    # a long reason is cut to its claim and wrapped to the panel's width
    d.info["envelope"]["outside"] = [
        "no scene in the data combines its thickness, force, area and pressures: the nearest "
        "lies 1.54 x the data's spacing away"
    ]
    fig = contact_figure({"linear": d}, None, [], tmp_path / "c.png")
    title = fig.panels[0].title
    assert " ".join(title.split()).endswith("combines its thickness, force, area and pressures")
    assert max(len(line) for line in title.splitlines()) <= 46
    d.info["physical"] = False  # an answer saved before the reasons were kept
    fig = contact_figure({"linear": d}, None, [], tmp_path / "c.png")
    title = " ".join(fig.panels[0].title.split())
    assert title.endswith("thickness, past 0.4, where the gel buckles: do not use"), title
    d.info["impossible"] = ["the object pulls on the skin (-0.2 N)"]
    fig = contact_figure({"linear": d}, None, [], tmp_path / "c.png")
    title = " ".join(fig.panels[0].title.split())
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
    titles = [p.title for p in fig.panels]
    assert titles[0].startswith("FEM (fine): failed, no answer")
    assert titles[3:6] == [
        "no answer",
        "contact pressure, peak 2 kPa",
        "contact pressure, peak 1 kPa",
    ], titles
    assert [label for label, _ in fig.bars] == [
        "displacement |u| (mm)",
        "contact pressure (kPa)",
    ]
    assert fig.panels[3].box[1] > fig.panels[0].box[3]  # the pressure row below the dents
    assert fig.bars[1][1][1] == fig.panels[3].box[1]  # each bar beside its row
    from stmpl import loads
    from stmpl.scene import Scene

    part = scene.part
    by_force = Scene(part, scene.thickness, loads.disk(part, 5, 0.02, 0.1).force)
    flat = Deformation(by_force, u, {"seconds": 0.001})
    one = contact_figure({"linear": flat})
    assert len(one.panels) == 1 and len(one.bars) == 1  # one panel and its bar
