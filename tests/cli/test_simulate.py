"""`stmpl simulate`, the main job: an object pressed on the arm, predicted, written, drawn."""

import json

import numpy as np
import pytest
import trimesh

from stmpl.cli.main import main


def test_the_default_grasp_squeezes_real_tissue(tmp_path, capsys, arm):
    """With no arguments: anny's right hand closes on the layered tissue of her left forearm
    until it squeezes 5 N, answered by the shipped grip model on the surface it was trained on
    (the once-subdivided arm): the dent, the squeeze met and the contact pressure, printed, drawn
    and kept; the answer says it lies outside what the model keeps its promise on.
    """
    assert main(["simulate", "--out-dir", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    arm = arm.subdivided(1)
    assert f"left_arm ({arm.n_vertices} vertices), 7.5 mm of skin and fat (the forearm" in out
    assert "right hand (whole) closed 2 mm from first touch" in out
    assert "(then closed until its squeeze is 5 N)" in out
    line = next(ln for ln in out.splitlines() if ln.startswith("gnn_forearm_grips"))
    assert float(line.split("squeeze ")[1].split(" N")[0]) == pytest.approx(5.0, rel=0.01)
    assert float(line.split("peak pressure ")[1].split(" kPa")[0]) > 1.0  # a firm grasp
    assert "NOTE: gnn_forearm_grips answers outside the data" in out
    body = trimesh.load(tmp_path / "pressed.ply", process=False)
    moved = np.linalg.norm(body.vertices - arm.vertices, axis=1)
    assert 1e-3 < moved.max() < 6e-3  # millimetres under a 5 N squeeze
    world = trimesh.load(tmp_path / "pressed.glb")
    assert arm.n_vertices in [len(g.vertices) for g in world.geometry.values()]
    assert len(world.geometry) == 2  # the arm and the hand
    record = json.loads((tmp_path / "simulate.json").read_text())
    assert record["answers"]["gnn_forearm_grips"]["reaction_N"] == pytest.approx(5.0, rel=0.01)
    assert (tmp_path / "simulate.png").stat().st_size > 30_000


def test_the_paper_s_grasp(tmp_path, capsys, arm):
    """``--tissue paper``: the paper's set-up, the shipped GNN of every body sharing 0.4 N over
    the skin anny's hand touches on the 1 kPa gel.
    """
    assert main(["simulate", "--tissue", "paper", "--out-dir", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "7.5 mm of the paper's 1 kPa gel; contact: right hand (whole) 0.4 N" in out
    assert "gnn_arm_bodies" in out and " ms" in out
    body = trimesh.load(tmp_path / "pressed.ply", process=False)
    moved = np.linalg.norm(body.vertices - arm.subdivided(1).vertices, axis=1)
    assert 1e-4 < moved.max() < 3e-3  # a dent of under a millimetre or so


def test_letters_against_the_fem(tmp_path, capsys, arm):
    assert (
        main(
            [
                "simulate",
                "--letters",
                "ECCV",
                "--force",
                "0.3",
                "--depth",
                "3",
                "--compare",
                "--res",
                "coarse",
                "--levels",
                "1",
                "--out-dir",
                str(tmp_path),
            ]
        )
        == 0
    )
    out = capsys.readouterr().out
    assert "letters ECCV" in out and "FEM (coarse)" in out
    line = [ln for ln in out.splitlines() if ln.strip().startswith("gnn_arm_bodies: MEE")][0]
    assert float(line.split("= ")[1].split(" %")[0]) < 10  # a coarse FEM, a fine model


@pytest.mark.parametrize(
    "argv,message",
    [
        (["--sphere", "8", "--letters", "A"], "choose one object"),
        (["--object", "missing.stl"], "mesh file not found"),
        (["--sphere", "8", "--depth", "-5"], "no contact"),
        (["--sphere", "8", "--depth", "500"], "depth 500 mm would sink the whole object"),
        (["--sphere", "0"], "--sphere needs a radius above 0 mm, got 0"),
        (["--sphere", "nan"], "--sphere needs a radius above 0 mm, got nan"),
        (["--letters", ""], "--letters needs some text"),
        (["--object", ""], "--object needs a mesh file's path"),
        (["--sphere", "8", "--grip", "pinch"], "--grip chooses how the hand grasps a limb"),
        (["--part", "belly", "--grip", "pinch"], "the belly has no limb to grasp"),
        (
            ["--given", "pose", "--part", "belly", "--model", "fem"],
            "the open hand has no pose to press to",
        ),
        (
            ["--sphere", "8", "--given", "pose"],
            "zoo:gnn_arm_bodies takes only a force on the skin: use --given force",
        ),
        (
            ["--tissue", "forearm", "--sphere", "8"],
            "learned the paper's 1 kPa gel, and --tissue asks for the forearm",
        ),
        (
            ["--weight", "0.9"],
            "knows anny's default body, not --weight 0.9: add --tissue paper",
        ),
        (
            ["--given", "force"],
            "zoo:gnn_forearm_grips takes only an object's pose: use --given pose",
        ),
    ],
)
def test_bad_requests_end_in_one_line(tmp_path, capsys, arm, argv, message):
    assert main(["simulate", *argv, "--out-dir", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err


def test_an_object_file_at_a_pose(tmp_path, capsys, arm):
    """A user's mesh file placed by --pose in body coordinates: a 1 cm sphere whose centre is
    8 mm inside the skin at a vertex touches that vertex.
    """
    from stmpl.contact import objects

    objects.sphere(0.01).apply_translation([0, 0, -0.01]).export(tmp_path / "ball.stl")
    k = 200
    centre = (arm.vertices[k] - 0.008 * arm.normals[k]) * 1e3  # mm
    assert (
        main(
            [
                "simulate",
                "--object",
                str(tmp_path / "ball.stl"),
                "--pose",
                *map(str, centre),
                "0",
                "0",
                "0",
                "--force",
                "0.2",
                "--out-dir",
                str(tmp_path / "o"),
            ]
        )
        == 0
    )
    out = capsys.readouterr().out
    assert "ball 0.2 N on" in out and "not watertight" not in out
    cup = objects.sphere(0.01).apply_translation([0, 0, -0.01])
    cup.update_faces(cup.face_normals[:, 2] < 0.9)  # the top cut open: a cup
    cup.export(tmp_path / "cup.stl")
    argv = ["simulate", "--object", str(tmp_path / "cup.stl"), "--force", "0.2"]
    assert main([*argv, "--out-dir", str(tmp_path / "c")]) == 0
    assert "note: cup.stl is not watertight" in capsys.readouterr().out
    assert (
        main(["simulate", "--pose", "0", "0", "0", "0", "0", "0", "--out-dir", str(tmp_path / "o")])
        == 2
    )
    assert "--pose places an --object" in capsys.readouterr().err


def test_the_engine_asked_for_a_model_that_has_none_is_refused_in_one_line(tmp_path, capsys):
    """``--engine numpy`` answers with a model's NumPy inference or not at all."""
    argv = ["simulate", "--engine", "numpy", "--model", "zoo:uv_unet_arm_bodies"]
    assert main([*argv, "--out-dir", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "a uv_unet model has no NumPy inference; those that do: ['gnn']" in err
    assert "Traceback" not in err and not (tmp_path / "simulate.png").exists()


def test_a_press_past_the_envelope_is_said_and_a_failed_fem_is_one_line(tmp_path, capsys, arm):
    """5 N on a fingertip-sized patch: the GNN answers with a note that the scene lies outside
    its data and a warning that the answer is impossible; the FEM fails and says why in one
    line; the command still writes the models' answers.
    """
    assert (
        main(
            [
                "simulate",
                "--sphere",
                "20",
                "--depth",
                "4",
                "--force",
                "5",
                "--compare",
                "--res",
                "coarse",
                "--levels",
                "1",
                "--out-dir",
                str(tmp_path),
            ]
        )
        == 0
    )
    out = capsys.readouterr().out
    assert "NOTE: gnn_arm_bodies answers outside the data" in out
    assert "mean pressure of a contact" in out
    assert "WARNING: gnn_arm_bodies: the skin moves inward" in out
    line = [ln for ln in out.splitlines() if ln.startswith("FEM (coarse)")][0]
    assert " ".join(line.split()).startswith("FEM (coarse) failed: the FEM solve failed at 5 N")
    assert "Traceback" not in out and (tmp_path / "simulate.png").is_file()
    found = json.loads((tmp_path / "simulate.json").read_text())
    assert found["fem"] is None and found["failed"]["FEM (coarse)"].startswith("the FEM solve")
    gnn = found["answers"]["gnn_arm_bodies"]
    assert not gnn["inside_envelope"] and not gnn["physical"] and gnn["outside_because"]
    strict = ["simulate", "--sphere", "20", "--depth", "4", "--force", "5", "--strict"]
    assert main([*strict, "--out-dir", str(tmp_path / "strict")]) == 2
    err = capsys.readouterr().err
    assert "gnn_arm_bodies: the scene lies outside the data" in err and "--strict refuses" in err
    assert not (tmp_path / "strict").exists()


def test_any_body_and_its_right_arm(tmp_path, capsys):
    """The default model serves another anny body (heavy, little muscle), its tissue from its
    weight by the paper's heuristic (0.9 -> 9.5 mm), and its right arm in the mirror, and says
    that this body's grasp lies outside the data it was trained on.
    """
    assert (
        main(
            [
                "simulate",
                "--weight",
                "0.9",
                "--muscle",
                "0.2",
                "--part",
                "right_arm",
                "--out-dir",
                str(tmp_path),
            ]
        )
        == 0
    )
    out = capsys.readouterr().out
    assert "right_arm (2109 vertices), 9.5 mm of the paper's 1 kPa gel" in out
    line = [ln for ln in out.splitlines() if ln.startswith("gnn_arm_bodies")][0]
    assert "answering in the mirror" in line
    # a heavy body's whole-hand grasp: no training scene (two bodies) combines its values
    assert "NOTE: gnn_arm_bodies answers outside the data" in out and "combines its" in out
    assert 0.1 < float(line.split("deepest")[1].split("mm")[0]) < 3.0


def test_the_belly_under_an_open_hand(tmp_path, capsys):
    """On the belly, a part with no limb to grasp, the default is anny's open hand laid on it,
    answered by the belly's own model of every body.
    """
    assert (
        main(
            [
                "simulate",
                "--part",
                "belly",
                "--force",
                "0.2",
                "--depth",
                "4",
                "--out-dir",
                str(tmp_path),
            ]
        )
        == 0
    )
    out = capsys.readouterr().out
    assert (
        "belly (977 vertices), 7.5 mm of the paper's 1 kPa gel" in out
        and "right hand (palm)" in out
    )
    line = [ln for ln in out.splitlines() if ln.startswith("gnn_belly_bodies")][0]
    assert 0.2 < float(line.split("deepest")[1].split("mm")[0]) < 5.0
    assert (tmp_path / "simulate.png").is_file()


def _reaction_said_and_kept(out: str, folder) -> None:
    """The FEM's line gives a reaction (a grip's squeeze) above zero, and simulate.json keeps
    the same.
    """
    line = next(ln for ln in out.splitlines() if ln.startswith("fem"))
    said = "squeeze " if "squeeze " in line else "reaction "
    reaction = float(line.split(said)[1].split(" N")[0])
    peak = float(line.split("peak pressure ")[1].split(" kPa")[0])
    record = json.loads((folder / "simulate.json").read_text())
    assert reaction > 0 and peak > 0
    assert record["answers"]["fem"]["reaction_N"] == pytest.approx(reaction, rel=1e-2)
    assert record["answers"]["fem"]["peak_pressure_kPa"] == pytest.approx(peak, rel=1e-2)


def test_a_fingertip_given_by_its_pose_answers_the_force_it_meets(tmp_path, capsys, arm):
    """``--given pose``: the ball stays where --depth puts it and the FEM answers the dent and
    the force: printed, in the picture's panel, in the meshes' notes and in simulate.json.
    """
    argv = ["simulate", "--sphere", "8", "--depth", "2", "--given", "pose", "--model", "fem"]
    argv += ["--res", "coarse", "--subdivide", "0", "--out-dir", str(tmp_path)]
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert "at its pose, the skin vertex nearest it" in out
    assert "(the force it meets is answered)" in out
    _reaction_said_and_kept(out, tmp_path)
    assert (tmp_path / "simulate.png").stat().st_size > 10_000


def test_a_fingertip_given_by_its_pose_and_a_force_is_pressed_until_it_meets_it(
    tmp_path, capsys, arm
):
    """``--given pose --force``: the ball starts where --depth puts it and the FEM presses it
    on until its reaction meets the force: said in the set-up line, met in the answer's line
    (within force control's tolerance) with how far it went, kept in simulate.json.
    """
    argv = ["simulate", "--sphere", "8", "--depth", "1", "--given", "pose", "--force", "0.01"]
    argv += ["--model", "fem", "--res", "coarse", "--subdivide", "0", "--out-dir", str(tmp_path)]
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert "(then pressed until it meets 0.01 N)" in out
    line = next(ln for ln in out.splitlines() if ln.startswith("fem"))
    assert float(line.split("reaction ")[1].split(" N")[0]) == pytest.approx(0.01, rel=0.006)
    moved = float(line.split("(pressed ")[1].split(" mm on from the pose")[0])
    assert 0 < moved < 10 and "by its own force control" in line
    took = line.split("mm  ")[1].split("  reaction")[0].strip()  # the whole force control's
    assert took != "0.0 ms" and float(took.split()[0]) > 0
    _reaction_said_and_kept(out, tmp_path)


def test_a_grasp_given_by_its_pose_answers_the_squeeze(tmp_path, capsys, arm):
    """``--given pose`` with the hand's grasp: the pinch closes 2 mm from first touch and the
    FEM, with dry skin's friction, answers the dent and the squeeze it meets (printed and in
    simulate.json); a strap has no pose to press to.
    """
    argv = ["simulate", "--grip", "pinch", "--along", "0.6", "--depth", "2", "--given", "pose"]
    argv += ["--model", "fem", "--res", "coarse", "--subdivide", "0", "--friction", "0.5"]
    argv += ["--out-dir", str(tmp_path)]
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert "right hand (pinch) closed 2 mm from first touch" in out
    assert "  squeeze " in next(ln for ln in out.splitlines() if ln.startswith("fem"))
    _reaction_said_and_kept(out, tmp_path)
    strap = ["simulate", "--strap", "--given", "pose", "--model", "fem"]
    assert main([*strap, "--out-dir", str(tmp_path)]) == 2
    assert "a strap or the open hand has no pose" in capsys.readouterr().err


def test_a_finger_that_cannot_curl_as_deep_is_said(tmp_path, capsys, arm):
    """The tripod 6 mm deep at 0.45 along anny's left arm: its middle finger cannot curl that
    far, and the run says so instead of sharing the force over two fingers unsaid.
    """
    argv = ["simulate", "--grip", "tripod", "--along", "0.45", "--depth", "6", "--tissue", "paper"]
    argv += ["--out-dir", str(tmp_path)]
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert "note: the tripod grip's middle finger cannot curl 6 mm into the limb" in out


class _Takes:
    def __init__(self, *takes):
        self.takes = takes


@pytest.mark.parametrize(
    "given,takes,way",
    [
        (None, [("pose",)], "pose"),  # a model trained on pressed objects
        (None, [("force",)], "force"),
        (None, [("force", "pose")], "force"),  # the FEM alone: the paper's load model
        (None, [("force", "pose"), ("pose",)], "pose"),
        ("pose", [("force", "pose")], "pose"),
        ("force", [("force", "pose"), ("force",)], "force"),
    ],
)
def test_the_scene_is_given_as_the_models_take_it(given, takes, way):
    from stmpl.cli.simulate import given_of

    specs = [f"m{k}" for k in range(len(takes))]
    assert given_of(given, specs, [_Takes(*t) for t in takes]) == way


def test_models_that_take_different_scenes_are_named():
    from stmpl.cli.simulate import given_of

    with pytest.raises(ValueError, match="m0 an object's pose; m1 a force on the skin"):
        given_of(None, ["m0", "m1"], [_Takes("pose"), _Takes("force")])
    with pytest.raises(ValueError, match="m1 takes only an object's pose: use --given pose"):
        given_of("force", ["m0", "m1"], [_Takes("force", "pose"), _Takes("pose")])


@pytest.mark.parametrize(
    "argv, res, force, tissue",
    [
        ([], "medium", 5.0, "forearm"),  # the grip model's data's mesh, its squeeze
        (["--res", "fine", "--force", "2"], "fine", 2.0, "forearm"),  # as asked
        (["--tissue", "paper"], "reference", 0.4, "paper"),
        (["--sphere", "8"], "reference", 0.4, None),  # the paper's model: its own tissue
    ],
)
def test_the_default_grasp_takes_its_model_s_set_up_unless_told(argv, res, force, tissue):
    from stmpl.cli.main import parser
    from stmpl.cli.simulate import models_of

    args = parser().parse_args(["simulate", *argv])
    models = models_of(args)
    assert (args.res, args.force, args.tissue) == (res, force, tissue)
    assert (models == ["zoo:gnn_forearm_grips"]) == (tissue == "forearm")
