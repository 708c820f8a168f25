"""What an answer is worth in words, and the facts a saved mesh carries."""

import io

import numpy as np
import trimesh

from stmpl.body.primitives import tube
from stmpl.scene import Deformation, Scene
from stmpl.viz.figures import mesh_bytes
from stmpl.viz.verdict import facts, verdict


def test_the_verdict_names_what_it_finds_first():
    assert verdict({"physical": True, "envelope": {"inside": True, "outside": []}})[0] == "inside"
    kind, words = verdict(
        {"physical": True, "envelope": {"inside": False, "outside": ["force 5 N > 0.5 N"]}}
    )
    assert kind == "outside" and "force 5 N > 0.5 N" in words
    kind, words = verdict(
        {
            "physical": False,
            "max_compression": 0.62,
            "envelope": {"inside": False, "outside": ["x"]},
        }
    )
    assert kind == "impossible" and "0.62" in words and "buckles" in words
    assert verdict({"physical": True, "envelope": None})[0] == "inside"
    # another model standing in for the chosen one is never shown as the chosen one's answer
    kind, words = verdict(
        {
            "physical": True,
            "envelope": {"inside": True, "outside": []},
            "stand_in": {"for": "gnn", "by": "naive"},
        }
    )
    assert kind == "outside" and words.startswith("a stand-in: naive answers while gnn's")


def test_a_saved_mesh_carries_its_verdict():
    """The facts of an answer outside its data travel in the GLB's extras and the PLY's header,
    and the files still read back as the same mesh with its colours.
    """
    part = tube()
    force = np.zeros(part.n_vertices)
    force[:5] = 0.1
    scene = Scene(part, np.full(part.n_vertices, 0.0075), force)
    u = np.zeros((part.n_vertices, 3))
    u[0, 2] = -0.002
    d = Deformation(
        scene, u, {"physical": True, "envelope": {"inside": False, "outside": ["force 5 N"]}}
    )
    about = facts(d, "gnn_arm")
    assert about["verdict"] == "outside" and "force 5 N" in about["why"]
    assert about["deepest_mm"] == 2.0 and abs(about["force_N"] - 0.5) < 1e-9
    mesh = part.mesh(d.vertices)
    mesh.visual.vertex_colors = np.tile([200, 10, 10, 255], (part.n_vertices, 1))
    glb = trimesh.load(io.BytesIO(mesh_bytes(mesh, "glb", about)), file_type="glb")
    assert glb.metadata["stmpl"]["verdict"] == "outside"
    ply = mesh_bytes(mesh, "ply", about)
    head = ply[: ply.index(b"end_header")].decode()
    assert "comment stmpl verdict: outside" in head and "comment stmpl why: outside" in head
    back = trimesh.load(io.BytesIO(ply), file_type="ply", process=False)
    assert np.allclose(back.vertices, d.vertices, atol=1e-6)
    assert (back.visual.vertex_colors[:, :3] == [200, 10, 10]).all()
