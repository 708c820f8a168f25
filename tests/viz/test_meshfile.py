"""PLY and GLB files written from arrays read back (by trimesh, as any viewer would) as the
same meshes: vertices, faces, colours, see-through objects and the facts in the scene's extras.
"""

import io

import numpy as np
import pytest
import trimesh

from stmpl.viz.meshfile import glb_bytes, ply_bytes


def _ball():
    return trimesh.creation.icosphere(2, 0.01)


def test_a_ply_reads_back_with_its_colours_and_comments():
    ball = _ball()
    colors = np.random.default_rng(0).integers(0, 256, (len(ball.vertices), 4), dtype=np.uint8)
    data = ply_bytes(ball.vertices, ball.faces, colors, ["stmpl verdict: outside", "a  b"])
    head = data[: data.index(b"end_header")].decode()
    assert head.splitlines()[2:4] == ["comment stmpl verdict: outside", "comment a b"]
    back = trimesh.load(io.BytesIO(data), file_type="ply", process=False)
    np.testing.assert_allclose(back.vertices, ball.vertices, atol=1e-7)
    np.testing.assert_array_equal(back.faces, ball.faces)
    np.testing.assert_array_equal(back.visual.vertex_colors, colors)
    plain = trimesh.load(io.BytesIO(ply_bytes(ball.vertices, ball.faces)), file_type="ply")
    assert len(plain.faces) == len(ball.faces)


def test_a_glb_holds_each_mesh_its_colours_and_the_facts():
    ball = _ball()
    box = trimesh.creation.box((0.02, 0.02, 0.02))
    colors = np.tile([200, 10, 10, 255], (len(ball.vertices), 1)).astype(np.uint8)
    facts = {"stmpl": {"verdict": "outside", "deepest_mm": 1.25}}
    data = glb_bytes(
        [
            {"name": "body", "vertices": ball.vertices, "faces": ball.faces, "colors": colors},
            {
                "name": "object0",
                "vertices": box.vertices,
                "faces": box.faces,
                "color": (150, 190, 255, 120),
            },
        ],
        facts,
    )
    assert data[:4] == b"glTF" and len(data) % 4 == 0
    scene = trimesh.load(io.BytesIO(data), file_type="glb", process=False)
    assert scene.metadata["stmpl"] == facts["stmpl"]
    body, obj = scene.geometry["body"], scene.geometry["object0"]
    np.testing.assert_allclose(body.vertices, ball.vertices, atol=1e-7)
    np.testing.assert_array_equal(body.faces, ball.faces)
    np.testing.assert_array_equal(body.visual.vertex_colors, colors)
    np.testing.assert_allclose(obj.vertices, box.vertices, atol=1e-7)
    material = obj.visual.material
    np.testing.assert_allclose(np.asarray(material.baseColorFactor), [150, 190, 255, 120], atol=1)
    assert material.alphaMode == "BLEND"


def test_colours_of_the_wrong_shape_or_type_are_refused():
    ball = _ball()
    with pytest.raises(ValueError, match=r"colours must be \(162, 4\) RGBA uint8"):
        ply_bytes(ball.vertices, ball.faces, np.zeros((162, 3), np.uint8))
    with pytest.raises(ValueError, match="RGBA uint8"):
        glb_bytes(
            [
                {
                    "name": "b",
                    "vertices": ball.vertices,
                    "faces": ball.faces,
                    "colors": np.zeros((162, 4)),
                }
            ]
        )
