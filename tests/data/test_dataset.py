"""The dataset format (stmpl/data/dataset.py): its hash is its content, and every read checks the
shards against the card.
"""

import json

import numpy as np
import pytest

from fem.generate import generate
from stmpl.data.dataset import Dataset
from stmpl.data.format import content_hash, part_hash


def test_dataset_errors_name_the_problem(tmp_path, tiny_config, capsys):
    import h5py

    with pytest.raises(FileNotFoundError, match="card.json"):
        Dataset(tmp_path)
    generate(tiny_config(thickness_mm=[7.5], forces=[0.05]), tmp_path / "d", progress=False)
    Dataset(tmp_path / "d").verify()
    with pytest.raises(ValueError, match="split must be"):
        Dataset(tmp_path / "d").arrays("training")
    first, second = sorted((tmp_path / "d").glob("shard-*.h5"))[:2]
    original = first.read_bytes()
    with h5py.File(first, "r+") as h:  # an edited sample: its file still reads
        h["displacement"][0, 0, 0] = 2 * h["displacement"][0, 0, 0] + 1e-6
    with pytest.raises(ValueError, match=f"{first.name} was changed after it was written"):
        Dataset(tmp_path / "d").arrays("train")
    card = Dataset(tmp_path / "d").card["hash"]
    generate(tiny_config(thickness_mm=[7.5], forces=[0.05]), tmp_path / "d", progress=True)
    assert f"{first.name} is unreadable, changed since it was written" in capsys.readouterr().out
    assert Dataset(tmp_path / "d").card["hash"] == card  # solved again, as it was
    first.write_bytes(original)
    second.write_bytes(second.read_bytes()[:200])  # a truncated shard
    with pytest.raises(ValueError, match=f"{second.name} is corrupt"):
        Dataset(tmp_path / "d").verify()


def test_the_hash_is_of_the_content(tmp_path, tiny_config):
    """The same samples give the same hash (timings differ between runs); an edited card or part
    does not pass.
    """
    cfg = tiny_config(thickness_mm=[7.5], forces=[0.05, 0.1])
    a = generate(cfg, tmp_path / "a", progress=False)
    b = generate(
        {**cfg, "parallel": {"backend": "serial", "workers": 1}, "name": "other"},
        tmp_path / "b",
        progress=False,
    )
    assert a["timing"]["solve_seconds_total"] != b["timing"]["solve_seconds_total"]
    assert a["hash"] == b["hash"] and len(a["hash"]) == 16
    card = json.loads((tmp_path / "b" / "card.json").read_text())
    card["hash"] = "0" * 16
    (tmp_path / "b" / "card.json").write_text(json.dumps(card))
    with pytest.raises(ValueError, match="does not match card.json"):
        Dataset(tmp_path / "b").arrays()


def test_the_card_hash_is_the_part_and_the_shards(ds):
    """The card's hash is recomputed from what is on disk: the part's and each shard's content
    hashes (those are in the card too, one per shard).
    """
    ds.verify()
    shards = [s["content"] for s in ds.card["shards"]]
    assert len(shards) == len(ds.shards) and len(set(shards)) == len(shards)
    assert content_hash(part_hash(ds.part), shards) == ds.card["hash"]
    assert content_hash(part_hash(ds.part), shards[::-1]) != ds.card["hash"]


def test_missing_and_foreign_folders_are_named(tmp_path):
    with pytest.raises(FileNotFoundError, match="dataset folder not found"):
        Dataset(tmp_path / "nowhere")
    (tmp_path / "card.json").write_text(json.dumps({"format": "something/9"}))
    with pytest.raises(ValueError, match="has format 'something/9'"):
        Dataset(tmp_path)
    (tmp_path / "card.json").write_text("{broken")
    with pytest.raises(ValueError, match="card.json is corrupt"):
        Dataset(tmp_path)


def test_splits_select_by_the_split_column(ds):
    a = ds.arrays()
    for i, name in enumerate(("train", "val", "test")):
        part = ds.arrays(name)
        n = ds.card["samples_per_split"][name]
        assert len(part["total"]) == int((a["split"] == i).sum()) == n
        np.testing.assert_array_equal(part["split"], i)


def test_datasets_of_one_part_read_as_one(tmp_path, tiny_config, tiny_dataset):
    """Two sets of one part and FEM set-up: their samples one after the other, placements and
    tasks kept distinct, a hash of both; another part or material is refused by name.
    """
    from stmpl.data.dataset import Datasets, open_data

    generate(
        tiny_config(
            name="few",
            thickness_mm=[7.5],
            forces=[0.05, 0.1],
            placements={"disk": {"centres": 3, "radii": [0.015]}},
        ),
        tmp_path / "few",
        progress=False,
    )
    a, b = Dataset(tiny_dataset), Dataset(tmp_path / "few")
    both = open_data([str(tiny_dataset), str(tmp_path / "few")])
    assert isinstance(both, Datasets) and len(both) == len(a) + len(b)
    assert both.card["name"] == "tiny+few" and both.card["hash"] not in (
        a.card["hash"],
        b.card["hash"],
    )
    assert both.card["config"]["thickness_mm"] == [5.0, 7.5, 10.0]
    x, y, xy = a.arrays("train"), b.arrays("train"), both.arrays("train")
    np.testing.assert_array_equal(
        xy["displacement"], np.concatenate([x["displacement"], y["displacement"]])
    )
    assert xy["params"] == x["params"] + y["params"]
    n = int(a.arrays()["placement"].max()) + 1
    np.testing.assert_array_equal(
        xy["placement"], np.concatenate([x["placement"], y["placement"] + n])
    )
    assert sum(both.card["samples_per_split"].values()) == len(both)
    generate(
        tiny_config(
            name="soft",
            thickness_mm=[7.5],
            forces=[0.05],
            material={"name": "neo_hookean", "E": 500.0, "nu": 0.4},
        ),
        tmp_path / "soft",
        progress=False,
    )
    with pytest.raises(ValueError, match=r"differ in their FEM set-up \(material\)"):
        Datasets([tiny_dataset, tmp_path / "soft"])
    generate(
        tiny_config(
            name="coarse",
            body={**tiny_config()["body"], "n_around": 12},
            thickness_mm=[7.5],
            forces=[0.05],
        ),
        tmp_path / "coarse",
        progress=False,
    )
    with pytest.raises(ValueError, match="live on different meshes"):
        Datasets([tiny_dataset, tmp_path / "coarse"])
    with pytest.raises(ValueError, match="empty list"):
        open_data([])
    assert len(both.parts) == 1 and not both.arrays()["body"].any()


def test_datasets_on_several_bodies_of_one_mesh(tmp_path, tiny_config, tiny_dataset):
    """The same tube mesh at another radius is another body: its samples say which (``body``
    indexes ``parts``), the card lists the bodies; the first body's samples come first.
    """
    from stmpl.data.dataset import open_data

    generate(
        tiny_config(
            name="thin",
            body={**tiny_config()["body"], "radius": 0.03},
            thickness_mm=[7.5],
            forces=[0.05],
        ),
        tmp_path / "thin",
        progress=False,
    )
    both = open_data([tiny_dataset, tmp_path / "thin"])
    a, b = Dataset(tiny_dataset), Dataset(tmp_path / "thin")
    assert len(both.parts) == 2 and np.array_equal(both.parts[1].vertices, b.part.vertices)
    assert np.abs(both.parts[0].vertices - both.parts[1].vertices).max() > 5e-3
    body = both.arrays()["body"]
    np.testing.assert_array_equal(body, np.r_[np.zeros(len(a), int), np.ones(len(b), int)])
    assert len(both.card["bodies"]) == 2


def test_the_same_body_built_again_is_one_body(tiny_dataset):
    """A part whose vertices differ from another's in their last digits (the same body built on
    another machine: 1e-15 m) is that body; a micrometre apart, another one.
    """
    from stmpl.data.dataset import SAME_BODY_M, bodies_of

    part = Dataset(tiny_dataset).part
    again = part.with_vertices(part.vertices * (1 + 1e-15))
    other = part.with_vertices(part.vertices + 1e-6)
    assert np.abs(again.vertices - part.vertices).max() < SAME_BODY_M
    assert part_hash(again) != part_hash(part)  # the bytes differ
    assert bodies_of([part, again, other, again, other]) == [0, 0, 1, 0, 1]


def test_a_linear_answer_is_kept_and_hashed(tmp_path, tiny_config):
    """With ``linear: true`` every sample carries the linear FEM's answer to its load, the
    operator's columns times the forces (a light press: within 3 % of the FEM's peak); an
    edited answer fails the content check.
    """
    import h5py

    from fem.compliance import local_compliance
    from fem.material import material

    cfg = tiny_config(
        thickness_mm=[7.5],
        forces=[0.01, 0.02],
        linear=True,
        placements={"disk": {"centres": 2, "radii": [0.02]}},
    )
    generate(cfg, tmp_path / "d", progress=False)
    ds = Dataset(tmp_path / "d")
    a = ds.arrays()
    assert a["linear"].shape == a["displacement"].shape
    i = 0
    loaded = np.flatnonzero(a["force"][i] > 0)
    G, _ = local_compliance(
        ds.part, 7.5e-3, loaded, cfg["resolution"], material(**ds.card["config"]["material"])
    )
    np.testing.assert_allclose(
        a["linear"][i], np.einsum("nkc,k->nc", G, a["force"][i][loaded]), rtol=1e-4, atol=1e-9
    )
    np.testing.assert_allclose(a["linear"][1], 2 * a["linear"][0], rtol=1e-5)  # 0.02 N, 0.01 N
    peak = np.linalg.norm(a["displacement"], axis=-1).max(1)
    lin = np.linalg.norm(a["linear"], axis=-1).max(1)
    assert np.all(np.abs(lin / peak - 1) < 0.03)
    shard = sorted((tmp_path / "d").glob("shard-*.h5"))[0]
    with h5py.File(shard, "r+") as h:
        h["linear"][0, 0, 0] += 1e-4
    with pytest.raises(ValueError, match="was changed after it was written"):
        Dataset(tmp_path / "d").arrays()


def test_a_broken_set_of_bodies_is_named(tmp_path):
    """bodies.json that is unreadable, of another format, or lists a member that is missing:
    one line naming the file.
    """
    from stmpl.data.dataset import BODIES_FORMAT, open_data

    (tmp_path / "bodies.json").write_text("{not json")
    with pytest.raises(ValueError, match="bodies.json is corrupt"):
        open_data(tmp_path)
    (tmp_path / "bodies.json").write_text(json.dumps({"format": "x", "members": []}))
    with pytest.raises(ValueError, match="has format 'x'"):
        open_data(tmp_path)
    (tmp_path / "bodies.json").write_text(
        json.dumps({"format": BODIES_FORMAT, "name": "b", "members": [{"folder": "body-00"}]})
    )
    with pytest.raises(FileNotFoundError, match="missing"):
        open_data(tmp_path)


def test_datasets_carry_their_tissue_and_refuse_to_mix_tissues(tmp_path, tiny_dataset):
    """Several sets read as one keep their tissue preset on the card (a model trained on them
    is judged by it); sets of two tissues are refused by name.
    """
    import json
    import shutil

    from stmpl.data.dataset import Datasets

    for name, tissue in (("a", "abdomen"), ("b", "abdomen"), ("c", "forearm")):
        shutil.copytree(tiny_dataset, tmp_path / name)
        card = json.loads((tmp_path / name / "card.json").read_text())
        (tmp_path / name / "card.json").write_text(json.dumps({**card, "tissue": tissue}))
    assert Datasets([tmp_path / "a", tmp_path / "b"]).card["tissue"] == "abdomen"
    assert Datasets([tiny_dataset, tiny_dataset]).card["tissue"] == "paper"
    with pytest.raises(ValueError, match=r"differ in their FEM set-up \(tissue\)"):
        Datasets([tmp_path / "a", tmp_path / "c"])
