"""The surface's tiles: every face in exactly one tile, and an answer that moves one place
sends only the tiles around it.
"""

import numpy as np
import pytest

from stmpl.body.primitives import tube
from stmpl.viewer.tiles import Tiles, cut


def test_tiles_cover_every_face_once_and_rebuild_the_mesh():
    part = tube(0.04, 0.3, 24, 40)
    groups = cut(part.vertices, part.faces, 8)
    assert len(groups) == 8
    assert np.array_equal(np.sort(np.concatenate(groups)), np.arange(len(part.faces)))
    t = Tiles(part.vertices, part.faces, 8)
    rebuilt = np.concatenate([used[local] for used, local in t.groups])
    assert np.array_equal(
        np.sort(rebuilt, axis=None), np.sort(part.faces[np.concatenate(groups)], axis=None)
    )
    with pytest.raises(ValueError, match="at least 1"):
        cut(part.vertices, part.faces, 0)


def test_a_local_change_sends_only_the_tiles_it_touches():
    part = tube(0.04, 0.3, 24, 40)
    t = Tiles(part.vertices, part.faces, 8)
    grey = np.full((part.n_vertices, 4), 200, np.uint8)
    assert t.changed(part.vertices, grey) == list(range(8))  # the first answer: all
    assert t.changed(part.vertices, grey) == []  # nothing moved
    moved = part.vertices.copy()
    end = np.argmin(part.vertices @ (part.vertices - part.vertices.mean(0))[0])
    near = np.linalg.norm(part.vertices - part.vertices[end], axis=1) < 0.02
    moved[near] -= 1e-3 * part.normals[near]
    sent = t.changed(moved, grey)
    assert 1 <= len(sent) <= 3
    t.forget()
    assert len(t.changed(moved, grey)) == 8


def test_a_change_no_one_sees_is_not_sent_nor_lost():
    """Moves under a twelfth of a pixel and colour steps of 3 are not sent; they are measured
    against what was sent, so two of them that add up to a visible change are.
    """
    part = tube(0.04, 0.3, 24, 40)
    t = Tiles(part.vertices, part.faces, 8)
    grey = np.full((part.n_vertices, 4), 200, np.uint8)
    t.changed(part.vertices, grey)
    step = 3e-5 * part.normals
    assert t.changed(part.vertices - step, grey) == []
    assert t.changed(part.vertices, grey + 3) == []
    assert t.changed(part.vertices - 2 * step, grey) == list(range(8))  # 60 um from what was sent
    assert t.changed(part.vertices - 2 * step, grey + 4) == list(range(8))
