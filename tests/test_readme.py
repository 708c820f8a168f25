"""The README works as written: its Python examples run and check their results, its first
command runs the main job on the shipped default, and CI runs its test command."""

import os
import pathlib
import re
import shlex

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parents[1]
TEXT = (ROOT / "README.md").read_text()


def _blocks(lang: str) -> list[str]:
    return re.findall(rf"```{lang}\n(.*?)```", TEXT, flags=re.S)


def test_readme_python_examples_run_and_hold(arm, tmp_path, monkeypatch):
    import trimesh

    monkeypatch.chdir(tmp_path)                   # the tour writes pressed_arm.ply here
    spaces = []
    for code in _blocks("python"):
        ns: dict = {}
        exec(compile(code, "README.md", "exec"), ns)
        spaces.append(ns)
    tour = spaces[0]
    d, scene = tour["d"], tour["scene"]
    arm = arm.subdivided(1)                       # the examples use the shipped models' skin
    assert d.info["predictor"] == "gnn" and d.scene is scene
    moved = np.linalg.norm(d.displacement, axis=1)
    assert moved[scene.force > 0].mean() > moved[scene.force == 0].mean()   # the dent is there
    mesh = trimesh.load(tmp_path / "pressed_arm.ply", process=False)
    np.testing.assert_allclose(mesh.vertices, scene.part.vertices + d.displacement, atol=1e-6)
    assert np.abs(scene.part.vertices - arm.vertices).max() > 1e-3   # the tour's own body
    pressing = spaces[1]                           # an object from a mesh file pressed on the arm
    touch, pressed = pressing["touch"], pressing["pressed"]
    assert pressed.scene.load.source is touch and touch.objects[0].name == "bar"
    glb = trimesh.load(tmp_path / "pressed_by_bar.glb", force="mesh", process=False)
    assert len(glb.vertices) == arm.n_vertices
    assert len(spaces) == 3 and spaces[2]["gnn"].part.n_vertices == arm.n_vertices


def test_the_two_setup_commands():
    """The first bash block runs the main job, the second the tests; CI runs the second."""
    main_job, tests = (b.strip() for b in _blocks("bash")[:2])
    assert main_job.startswith("pip install torch==2.13.0 && pip install -e . && stmpl ")
    assert tests.endswith("python -m pytest -q")
    assert tests in (ROOT / ".ci" / "run").read_text()


def test_readme_main_command_runs_on_the_shipped_default(tmp_path, capsys, arm, monkeypatch):
    from stmpl.cli import main

    command = _blocks("bash")[0].strip().split(" && ")[-1]
    argv = shlex.split(command)
    assert argv[0] == "stmpl"
    monkeypatch.chdir(tmp_path)
    assert main(argv[1:]) == 0
    out = capsys.readouterr().out
    assert "gnn_arm" in out and "right hand" in out
    for f in ("simulate.png", "pressed.glb", "pressed.ply"):
        assert os.path.getsize(tmp_path / "simulate_out" / f) > 20_000, f
