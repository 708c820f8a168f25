"""Training presses twice, as solved and in the mirror (stmpl/pipeline/mirrored.py)."""

import numpy as np
import pytest

from stmpl.body.mirror import self_mirror
from stmpl.pipeline import mirrored
from stmpl.pipeline.train import train
from tests.body.test_mirror import symmetric_sheet


class _Set:
    """A dataset on the symmetric sheet whose splits hold the given placements."""

    def __init__(self, splits):
        self.part = symmetric_sheet()
        self.parts = [self.part]
        self.splits = splits

    def arrays(self, split):
        kinds = [k for k, _ in self.splits[split]]
        return {"kind": kinds, "params": [p for _, p in self.splits[split]]}


def _press(at, radius=0.01):
    return ("press_disk", {"at": at, "radius": radius, "depth": 0.003, "reaction": 2.0})


def test_a_mirrored_press_has_its_fields_at_the_twins_and_its_vectors_turned():
    part = symmetric_sheet()
    twin = self_mirror(part)
    n, rng = part.n_vertices, np.random.default_rng(0)
    a = {
        "thickness": rng.random((3, n)),
        "gap": rng.random((3, n)),
        "displacement": rng.random((3, n, 3)),
        "body": np.zeros(3, int),
        "total": np.array([1.0, 2.0, 5.0]),
    }
    out, keep = mirrored.with_mirrored(a, np.array([0, 2]), twin)
    assert list(keep) == [0, 1, 2, 3] and list(out["total"]) == [1.0, 5.0, 1.0, 5.0]
    np.testing.assert_array_equal(out["gap"][3, twin], a["gap"][2])
    np.testing.assert_array_equal(out["gap"][1], a["gap"][2])
    u, m = a["displacement"][0], out["displacement"][2]
    np.testing.assert_array_equal(m[twin], u * [-1.0, 1.0, 1.0])  # x turned, y and z kept
    again, _ = mirrored.with_mirrored(out, np.array([2]), twin)  # twice mirrored: as solved
    np.testing.assert_array_equal(again["displacement"][1], u)


def test_a_training_place_whose_twin_is_validated_or_tested_is_left_out():
    """The twins of the validated place (vertex 42, twin 62) and the tested one (vertex 0, a
    corner, twin 20) are left out of training; a place on the mirror plane (vertex 10), a
    2 cm disk at 20 (another object) and a place whose twin is unseen stay.
    """
    twin = self_mirror(symmetric_sheet())
    assert (twin[0], twin[42], twin[44]) == (20, 62, 60)
    ds = _Set({"val": [_press(42)], "test": [_press(0)]})
    train_places = [_press(20), _press(10), _press(20, radius=0.02), _press(62), _press(44)]
    a = {"kind": [k for k, _ in train_places], "params": [p for _, p in train_places]}
    assert list(mirrored.held_out(ds, a, np.arange(5), twin)) == [1, 2, 4]
    grasp = {"kind": ["grasp"], "params": [{"along": 0.5, "around": 0.0}]}
    with pytest.raises(ValueError, match="grasp has no centre vertex"):
        mirrored.held_out(ds, grasp, np.arange(1), twin)


def test_mirror_needs_a_part_that_is_its_own_mirror_image(tiny_dataset, tmp_path):
    cfg = {"name": "n", "model": "naive", "data": str(tiny_dataset), "epochs": 1}
    with pytest.raises(ValueError, match="mirror must be true or false"):
        train({**cfg, "mirror": "yes", "out": str(tmp_path / "a")}, progress=False)
    with pytest.raises(ValueError, match="needs a part that is its own mirror image; tube"):
        train({**cfg, "mirror": True, "out": str(tmp_path / "b")}, progress=False)
