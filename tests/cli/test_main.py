import numpy as np
import pytest

from stmpl.cli.main import main
from stmpl.scene import Scene


def test_scene_command_writes_picture_scene_and_mesh(tmp_path, capsys, arm):
    rc = main(
        [
            "scene",
            "--load",
            "disk",
            "--force",
            "5",
            "--out",
            str(tmp_path / "s.png"),
            "--save",
            str(tmp_path / "s.npz"),
            "--export",
            str(tmp_path / "s.ply"),
        ]
    )
    assert rc == 0
    assert (tmp_path / "s.png").stat().st_size > 20_000
    s = Scene.read(tmp_path / "s.npz")
    assert s.force.sum() == pytest.approx(5.0)
    np.testing.assert_allclose(s.thickness, 0.0075)  # weight 0.5 -> 7.5 mm
    assert "disk: 5 N on" in capsys.readouterr().out


def test_scene_of_spots(tmp_path, capsys, arm):
    """``--load spots``: several fingertip-sized disks sharing the force."""
    s = tmp_path / "s.npz"
    assert (
        main(
            [
                "scene",
                "--load",
                "spots",
                "--count",
                "4",
                "--radius",
                "8",
                "--force",
                "0.4",
                "--out",
                str(tmp_path / "s.png"),
                "--save",
                str(s),
            ]
        )
        == 0
    )
    sc = Scene.read(s)
    from stmpl import loads

    ld = loads.spots(arm, uv=(0.45, 0.5), count=4, radius=0.008, spread=0.04, total=0.4)
    assert sc.force.sum() == pytest.approx(0.4) and np.count_nonzero(sc.force) == ld.count
    assert "spots: 0.4 N on" in capsys.readouterr().out


def test_scene_command_reports_bad_input(capsys, arm):
    assert main(["scene", "--force", "-1"]) == 2
    assert "total force must be finite and > 0" in capsys.readouterr().err
    assert main(["scene", "--part", "leg"]) == 2
    assert "unknown part 'leg'" in capsys.readouterr().err
    assert main(["scene", "--thickness", "20"]) == 2
    assert "thickness must lie in" in capsys.readouterr().err


def test_parts_command(capsys, arm):
    assert main(["parts"]) == 0
    out = capsys.readouterr().out
    assert "left_arm" in out and "541" in out and "belly" in out


def test_simulate_command_solves_draws_and_saves(tmp_path, capsys, arm):
    from stmpl.scene import Deformation

    rc = main(
        [
            "solve",
            "--force",
            "0.1",
            "--levels",
            "2",
            "--res",
            "medium",
            "--out",
            str(tmp_path / "f.png"),
            "--save",
            str(tmp_path / "d.npz"),
            "--vtu",
            str(tmp_path / "s.vtu"),
        ]
    )
    assert rc == 0
    out = capsys.readouterr().out
    assert out.count(" ok ") == 2 and "wrote" in out
    d = Deformation.read(tmp_path / "d.npz")
    assert 1e-4 < d.magnitude.max() < 7.5e-3  # pressed in, not through the layer
    loaded = d.scene.force > 0
    assert np.all(
        np.einsum("ni,ni->n", d.displacement[loaded], d.scene.part.normals[loaded]) < 0
    )  # inward
    assert (tmp_path / "f.png").stat().st_size > 20_000 and (tmp_path / "s.vtu").exists()


def test_simulate_command_reports_a_failed_solve(capsys, arm):
    assert (
        main(
            [
                "solve",
                "--force",
                "8",
                "--levels",
                "1",
                "--res",
                "coarse",
                "--radius",
                "10",
                "--at",
                "0.5",
                "0.5",
            ]
        )
        == 2
    )
    err = capsys.readouterr().err
    assert "FEM solve failed" in err and "Traceback" not in err and err.count("\n") == 1


def test_predict_command_runs_a_checkpoint_against_the_fem(tmp_path, capsys, arm):
    import torch

    from stmpl import predictor
    from stmpl.scene import Deformation

    torch.manual_seed(0)
    p = predictor.create("uv_unet", arm, {"size": 64, "width": 4, "depth": 3})
    ckpt = p.save(tmp_path / "tiny_unet.safetensors")
    rc = main(
        [
            "predict",
            "--model",
            str(ckpt),
            "--force",
            "0.1",
            "--compare",
            "--res",
            "coarse",
            "--levels",
            "1",
            "--out",
            str(tmp_path / "p.png"),
        ]
    )
    out = capsys.readouterr().out
    assert rc == 0 and (tmp_path / "p.png").stat().st_size > 20_000
    assert "tiny_unet" in out and "FEM (coarse)" in out and "MEE" in out
    assert (
        main(["predict", "--model", str(ckpt), "--force", "0.1", "--save", str(tmp_path / "d.npz")])
        == 0
    )
    d = Deformation.read(tmp_path / "d.npz")
    np.testing.assert_allclose(d.displacement, p.predict(d.scene).displacement, atol=1e-9)
    assert main(["predict", "--model", "zoo:nope", "--force", "0.1"]) == 2
    assert "zoo" in capsys.readouterr().err  # no zoo there, or no model "nope" in it


def test_predict_says_when_a_scene_lies_outside_the_models_data(capsys, arm):
    """The outside evaluation's case: 5 N on a 2 cm disk. The shipped GNN answers (exit 0) with
    one note naming the axes the scene leaves and one warning that the answer lies past where
    the gel buckles, beside its line, as ``stmpl simulate`` says them.
    """
    assert main(["predict", "--force", "5", "--thickness", "7.5"]) == 0
    out = capsys.readouterr().out
    notes = [ln for ln in out.splitlines() if ln.lstrip().startswith(("NOTE", "WARNING"))]
    assert len(notes) == 2, out
    assert "answers outside the data it was trained and checked on" in notes[0]
    assert "force of a contact 5 N > 0.5 N" in notes[0] and "kPa" in notes[0]
    assert "past 0.4, where the gel buckles" in notes[1] and "do not use this answer" in notes[1]
    assert main(["predict", "--force", "0.3", "--thickness", "7.5"]) == 0
    out = capsys.readouterr().out
    assert "NOTE" not in out and "WARNING" not in out


def _fails(argv, capsys, message):
    """``stmpl argv`` ends with exit code 2 and one error line naming the problem (argparse
    adds its usage line before it), no traceback.
    """
    try:
        rc = main(argv)
    except SystemExit as e:  # argparse's own refusals
        rc = e.code
    err = capsys.readouterr().err
    assert rc == 2, err
    assert message in err and "Traceback" not in err, err
    lines = [ln for ln in err.splitlines() if ln.strip() and not ln.startswith(("usage:", " "))]
    assert len(lines) == 1, err


def test_expected_failures_end_in_one_line(tmp_path, capsys, arm):
    blocker = tmp_path / "a-file"
    blocker.write_text("not a folder")
    broken = tmp_path / "broken.yaml"
    broken.write_text("model: naive\ndata: [x\n")
    _fails(["scene", "--force", "0.3", "--out", str(blocker / "x.png")], capsys, str(blocker))
    _fails(["train", str(broken)], capsys, "broken.yaml is not valid YAML")
    _fails(["train", str(tmp_path / "missing.yaml")], capsys, "training config file not found")
    _fails(
        ["evaluate", "fem", "--data", str(tmp_path / "nothing")], capsys, "dataset folder not found"
    )
    _fails(
        ["evaluate", "fem", "--data", str(tmp_path), "--limit", "-1"],
        capsys,
        "must be an integer >= 1, got '-1'",
    )
    _fails(["solve", "--tissue", "gel"], capsys, "unknown tissue preset 'gel'")
    _fails(["simulate", "--friction", "-1"], capsys, "--friction: must be a number >= 0, got '-1'")
    _fails(["simulate", "--friction", "nan"], capsys, "--friction: must be a number >= 0")
    _fails(["predict", "--device", "tpu"], capsys, "unknown device 'tpu'")
    _fails(["predict", "--device", "cuda:7"], capsys, "device cuda:7 is not available")
    _fails(
        ["predict", "--model", str(tmp_path / "none.safetensors")], capsys, "checkpoint not found"
    )
    _fails(["scene", "--load", "letter", "--char", "\u6f22"], capsys, "not in the letter font")


def test_verbose_shows_the_traceback(tmp_path, capsys):
    broken = tmp_path / "broken.yaml"
    broken.write_text("model: naive\ndata: [x\n")
    assert main(["-v", "train", str(broken)]) == 2
    err = capsys.readouterr().err
    assert "Traceback" in err and "not valid YAML" in err


def test_a_permission_error_is_one_line(tmp_path, capsys, arm, monkeypatch):
    """An output the user may not write (simulated: the tests run as root, who may write
    anywhere) ends in one line naming the file.
    """
    import stmpl.viz.figures

    target = tmp_path / "locked.png"

    def refuse(fig, path, dpi):
        raise PermissionError(13, "Permission denied", str(path))

    monkeypatch.setattr(stmpl.viz.figures, "save_figure", refuse)
    _fails(
        ["scene", "--force", "0.3", "--out", str(target)], capsys, f"Permission denied: {target}"
    )


def test_any_anny_phenotype_makes_the_scene_and_a_learned_model_refuses_it(tmp_path, capsys, arm):
    """``--muscle``, ``--height``, ...: the scene is on that body (its arm differs from the
    default one), and a model trained on the default body refuses it in one line.
    """
    s = tmp_path / "s.npz"
    assert (
        main(
            [
                "scene",
                "--muscle",
                "0.9",
                "--height",
                "0.8",
                "--force",
                "0.2",
                "--out",
                str(tmp_path / "s.png"),
                "--save",
                str(s),
            ]
        )
        == 0
    )
    part = Scene.read(s).part
    assert part.source["options"]["phenotype"]["muscle"] == 0.9
    assert part.n_vertices == arm.n_vertices
    assert np.abs(part.vertices - arm.vertices).max() > 1e-3  # another arm
    capsys.readouterr()
    assert (
        main(
            [
                "predict",
                "--muscle",
                "0.9",
                "--model",
                "zoo:linear_arm",
                "--out",
                str(tmp_path / "p.png"),
            ]
        )
        == 2
    )
    assert "another body part" in capsys.readouterr().err
    assert main(["scene", "--age", "1.5"]) == 2
    assert "age must be in [0, 1]" in capsys.readouterr().err


def test_evaluate_reads_several_dataset_folders_as_one(tmp_path, capsys, tiny_dataset, ds, make):
    """``stmpl evaluate --data A B``: the two folders' splits measured together."""
    import shutil

    ckpt = make("naive", ds).save(tmp_path / "naive.safetensors")
    shutil.copytree(tiny_dataset, tmp_path / "again")
    n = len(ds.arrays("test")["total"])
    for data, samples in (
        ([str(tiny_dataset)], n),
        ([str(tiny_dataset), str(tmp_path / "again")], 2 * n),
    ):
        assert main(["evaluate", str(ckpt), "--data", *data, "--split", "test"]) == 0
        row = [line for line in capsys.readouterr().out.splitlines() if "naive" in line][-1]
        assert row.split("|")[2].strip() == str(samples)


def test_a_stop_that_lands_in_a_finaliser_is_raised_again_after_it():
    """SIGTERM's :class:`Stopped` raised inside a weak reference's callback, where Python
    prints an exception and drops it, comes again as soon as the callback returns: the run
    stops, as it would anywhere else.
    """
    import signal
    import time
    import weakref

    from stmpl.cli.main import Stopped, _stop, stoppable

    class Thing:
        pass

    with stoppable():
        thing = Thing()
        ref = weakref.ref(thing, lambda r: _stop(signal.SIGTERM, None))
        with pytest.raises(Stopped):
            del thing  # the callback's Stopped is dropped here ...
            for _ in range(200):  # ... and raised again here
                time.sleep(0.005)
        assert ref() is None
