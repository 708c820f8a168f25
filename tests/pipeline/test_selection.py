"""Which samples a training config takes, and the envelope they back
(stmpl/pipeline/selection.py).
"""

import numpy as np
import pytest

from stmpl.data.dataset import Dataset
from stmpl.data.format import at_levels
from stmpl.pipeline.selection import envelope, selection
from stmpl.pipeline.train import read_config


def _cfg(**over):
    return read_config({"model": "naive", "data": "x", **over})


def test_a_share_of_the_placements_keeps_whole_placements_the_same_each_time(tiny_dataset):
    ds = Dataset(tiny_dataset)
    a, every = selection(ds, "train", _cfg())
    assert every.tolist() == list(range(len(a["total"])))
    places = np.unique(a["placement"])
    _, half = selection(ds, "train", _cfg(train_fraction=0.5, seed=3))
    kept = np.unique(a["placement"][half])
    assert len(kept) == round(0.5 * len(places))
    np.testing.assert_array_equal(half, np.flatnonzero(np.isin(a["placement"], kept)))
    np.testing.assert_array_equal(half, selection(ds, "train", _cfg(train_fraction=0.5, seed=3))[1])
    # the share is of training only: validation keeps every sample
    v, val = selection(ds, "val", _cfg(train_fraction=0.5, seed=3))
    assert len(val) == len(v["total"])


def test_thickness_levels_and_a_cap_on_the_samples(tiny_dataset):
    ds = Dataset(tiny_dataset)
    a, _ = selection(ds, "train", _cfg())
    level = float(np.median(a["thickness"][0])) * 1e3
    _, thin = selection(ds, "train", _cfg(thickness_mm=[level]))
    assert 0 < len(thin) < len(a["total"])
    np.testing.assert_array_equal(thin, np.flatnonzero(at_levels(a, [level])))
    _, first = selection(ds, "train", _cfg(max_train=5))
    assert first.tolist() == [0, 1, 2, 3, 4]


def test_the_envelope_counts_the_training_scenes_and_refuses_none(tiny_dataset):
    ds = Dataset(tiny_dataset)
    a, keep = selection(ds, "train", _cfg())
    env = envelope(ds, _cfg())
    assert env.info["training"]["scenes"] == len(keep)
    with pytest.raises(ValueError, match="has no training samples"):
        envelope(ds, _cfg(thickness_mm=[42.0]))
