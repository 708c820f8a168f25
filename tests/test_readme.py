"""The README and the API page work as written: their Python examples run and check their
results, the README's first command runs the main job on the shipped default, CI runs its test
command, and the README stays a front door.
"""

import os
import pathlib
import re
import shlex

import numpy as np
import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]
TEXT = (ROOT / "README.md").read_text()
API = (ROOT / "docs" / "api.md").read_text()
MAX_LINES = 150
"""A front door: what stmpl is, a picture, two commands, an example, one table, links."""


def _blocks(lang: str, text: str = TEXT) -> list[str]:
    return re.findall(rf"```{lang}\n(.*?)```", text, flags=re.S)


def _run(code: str, name: str) -> dict:
    ns: dict = {}
    exec(compile(code, name, "exec"), ns)
    return ns


def test_the_readme_is_a_front_door():
    assert len(TEXT.splitlines()) <= MAX_LINES
    assert len(_blocks("python")) == 1 and len(_blocks("bash")) == 2


def test_readme_python_example_runs_and_holds(arm, tmp_path, monkeypatch):
    import trimesh

    monkeypatch.chdir(tmp_path)
    ns = _run(_blocks("python")[0], "README.md")
    d, scene = ns["d"], ns["scene"]
    assert d.info["predictor"] == "gnn" and d.scene is scene and scene.part.n_vertices == 2109
    moved = np.linalg.norm(d.displacement, axis=1)
    assert moved[scene.force > 0].mean() > 5 * moved[scene.force == 0].mean()  # the dent
    mesh = trimesh.load(tmp_path / "pressed_arm.ply", process=False)
    np.testing.assert_allclose(mesh.vertices, scene.part.vertices + d.displacement, atol=1e-6)


def test_api_page_examples_run_and_hold(arm, tmp_path, monkeypatch):
    import trimesh

    monkeypatch.chdir(tmp_path)  # the tour writes pressed_arm.ply here
    spaces = [_run(code, "docs/api.md") for code in _blocks("python", API)]
    tour = spaces[0]
    d, scene = tour["d"], tour["scene"]
    arm = arm.subdivided(1)  # the examples use the shipped models' skin
    assert d.info["predictor"] == "gnn" and d.scene is scene
    moved = np.linalg.norm(d.displacement, axis=1)
    assert moved[scene.force > 0].mean() > moved[scene.force == 0].mean()  # the dent is there
    mesh = trimesh.load(tmp_path / "pressed_arm.ply", process=False)
    np.testing.assert_allclose(mesh.vertices, scene.part.vertices + d.displacement, atol=1e-6)
    assert np.abs(scene.part.vertices - arm.vertices).max() > 1e-3  # the tour's own body
    pressing = spaces[1]  # an object from a mesh file pressed on the arm
    touch, pressed = pressing["touch"], pressing["pressed"]
    assert pressed.scene.load.source is touch and touch.objects[0].name == "bar"
    glb = trimesh.load(tmp_path / "pressed_by_bar.glb", force="mesh", process=False)
    assert len(glb.vertices) == arm.n_vertices
    posing = spaces[2]  # a fingertip given by its pose, answered by the FEM with its force
    assert posing["scene"].given == "pose" and posing["answer"].reaction > 0.1
    assert posing["pressed"].reaction == pytest.approx(0.5, rel=0.005)  # force control met it
    assert len(spaces) == 4 and spaces[3]["gnn"].part.n_vertices == arm.n_vertices


def test_the_two_setup_commands():
    """The first bash block runs the main job, the second the tests; CI runs the second."""
    main_job, tests = (b.strip() for b in _blocks("bash")[:2])
    assert main_job.startswith("pip install torch==2.13.0 && pip install -e . && stmpl ")
    assert tests.endswith("python -m pytest -q")
    assert tests in (ROOT / ".ci" / "run").read_text()


def test_readme_main_command_runs_on_the_shipped_default(tmp_path, capsys, arm, monkeypatch):
    from stmpl.cli.main import main

    command = _blocks("bash")[0].strip().split(" && ")[-1]
    argv = shlex.split(command)
    assert argv[0] == "stmpl"
    monkeypatch.chdir(tmp_path)
    assert main(argv[1:]) == 0
    out = capsys.readouterr().out
    assert "gnn_forearm_grips" in out and "right hand" in out
    squeeze = re.search(r"gnn_forearm_grips .* squeeze ([0-9.]+) N", out)
    assert squeeze and float(squeeze.group(1)) == pytest.approx(5.0, rel=0.01), out  # 1 %
    for f in ("simulate.png", "pressed.glb", "pressed.ply"):
        assert os.path.getsize(tmp_path / "simulate_out" / f) > 20_000, f
