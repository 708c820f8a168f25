"""Datasets across bodies (fem/bodies.py): the config's bodies, their thickness from weight, anny's
sampler, and a tiny set made on two anny bodies and read back as one.
"""

import json

import numpy as np
import pytest

from fem.bodies import members, sample_phenotypes
from fem.config import config_hash, read_config
from fem.generate import generate

BASE = {
    "name": "two",
    "body": {"model": "anny"},
    "part": "left_arm",
    "resolution": "coarse",
    "forces": [0.1],
    "linear": True,
    "placements": {"disk": {"centres": 1, "radii": [0.02]}},
    "splits": [0.0, 0.0, 1.0],
    "parallel": {"backend": "serial", "workers": 1},
}


def _cfg(**over):
    return {**BASE, **over}


def test_bodies_are_checked():
    for bad, match in (
        ({"phenotypes": []}, "empty"),
        ({"phenotypes": [{"weight": 1.5}]}, "weight must be in"),
        ({"phenotypes": [{"wieght": 0.5}]}, "unknown anny phenotype"),
        ({"sample": {"count": 0}}, "count"),
        ({"sample": {"count": 2, "age": [70, 20]}}, "age"),
        ({"thickness": "from_weight"}, "phenotypes and/or sample"),
        ({"phenotypes": [{}], "thickness": "heuristic"}, "bodies.thickness"),
    ):
        with pytest.raises(ValueError, match=match):
            read_config(_cfg(bodies=bad))
    with pytest.raises(ValueError, match="only anny bodies"):
        read_config(
            _cfg(
                bodies={"phenotypes": [{}]},
                body={"model": "tube", "radius": 0.04, "length": 0.2},
                part="tube",
            )
        )
    with pytest.raises(ValueError, match="not body.phenotype"):
        read_config(
            _cfg(bodies={"phenotypes": [{}]}, body={"model": "anny", "phenotype": {"weight": 0.2}})
        )


def test_old_configs_keep_their_hash():
    """``linear`` and ``bodies`` at their defaults leave a config's hash as before they existed."""
    cfg = read_config(_cfg(linear=False))
    assert config_hash(cfg) == config_hash(
        {k: v for k, v in cfg.items() if k not in ("linear", "bodies")}
    )
    assert config_hash(read_config(_cfg())) != config_hash(cfg)


def test_members_take_thickness_from_weight():
    """The paper's heuristic: 5 mm at weight 0, 10 mm at 1; ``levels`` keeps the config's."""
    cfg = read_config(
        _cfg(bodies={"phenotypes": [{"weight": 0.0}, {"weight": 0.37}, {"muscle": 0.9}]}, seed=4)
    )
    ms = members(cfg)
    assert [m["thickness_mm"] for m in ms] == [[5.0], [6.85], [7.5]]
    assert [m["name"] for m in ms] == ["two-body00", "two-body01", "two-body02"]
    assert [m["seed"] for m in ms] == [4, 5, 6]
    assert ms[2]["body"] == {"model": "anny", "phenotype": {"muscle": 0.9}}
    assert all("bodies" not in m for m in ms)
    cfg = read_config(
        _cfg(
            bodies={"phenotypes": [{"weight": 0.0}], "thickness": "levels"}, thickness_mm=[6.0, 8.0]
        )
    )
    assert members(cfg)[0]["thickness_mm"] == [6.0, 8.0]


def test_anny_sampler_is_seeded_and_adult():
    a, b = sample_phenotypes(4, seed=7), sample_phenotypes(4, seed=7)
    assert a == b and a != sample_phenotypes(4, seed=8)
    assert all(0.0 <= v <= 1.0 for ph in a for v in ph.values())
    kids = sample_phenotypes(4, seed=7, age=[2, 6])
    assert max(ph["age"] for ph in kids) < min(ph["age"] for ph in a)


def test_two_bodies_make_one_set(tmp_path):
    """Each body its own dataset (its own arm, its own thickness, the linear FEM's answer on its
    own arm), read back as one set whose samples say which body; a second run redoes nothing.
    """
    from stmpl.data.dataset import Datasets, open_data

    cfg = _cfg(bodies={"phenotypes": [{}, {"weight": 0.9, "muscle": 0.8}]})  # {}: the default
    assert generate(cfg, tmp_path / "two", progress=False, max_bodies=1) == {}
    assert (tmp_path / "two" / "body-00" / "card.json").is_file()
    assert not (tmp_path / "two" / "body-01").exists()
    card = generate(cfg, tmp_path / "two", progress=False)
    assert [m["thickness_mm"] for m in card["members"]] == [[7.5], [9.5]]
    assert card["members"][0]["phenotype"] == {}
    ds = open_data(tmp_path / "two")
    assert isinstance(ds, Datasets) and len(ds.parts) == 2 and ds.card["name"] == "two"
    a = ds.arrays("test")
    assert set(a["body"]) == {0, 1}
    for b, t in ((0, 7.5e-3), (1, 9.5e-3)):
        np.testing.assert_allclose(a["thickness"][a["body"] == b], t, rtol=1e-6)
    assert np.abs(ds.parts[0].vertices - ds.parts[1].vertices).max() > 2e-3  # another arm
    heavy = a["body"] == 1
    lin = np.linalg.norm(a["linear"], axis=-1).max(1)
    fem = np.linalg.norm(a["displacement"], axis=-1).max(1)
    assert np.all(np.abs(lin / fem - 1) < 0.15)
    assert lin[heavy].mean() > lin[~heavy].mean()  # thicker tissue gives more
    again = generate(cfg, tmp_path / "two", progress=False)
    assert again["hash"] == card["hash"]
    assert json.loads((tmp_path / "two" / "bodies.json").read_text())["hash"] == card["hash"]
    with pytest.raises(ValueError, match="different config"):
        generate({**cfg, "forces": [0.2]}, tmp_path / "two", progress=False)


def test_smpl_format_bodies_run_the_same_path(tmp_path):
    """Bodies of a small SMPL-format file made here (beta_2 fattens its arm): a dataset across
    two betas (thickness from beta_2, the paper's heuristic), a GNN of every body trained on it,
    and a prediction on a third beta no dataset holds, through the public API, within a few
    per cent of the FEM there.
    """
    from fem.predictor import FEMPredictor
    from stmpl import loads, predictor, tissue
    from stmpl.body.spec import part_from_spec
    from stmpl.metrics import sample_metrics
    from stmpl.pipeline.train import train
    from stmpl.scene import Scene
    from tests.body.test_smpl_body import _model, _write_obj

    data, t = _model()
    np.savez(tmp_path / "model.npz", **data)
    _write_obj(tmp_path / "uv.obj", t, data["f"])
    body = {
        "model": "smpl",
        "path": str(tmp_path / "model.npz"),
        "uv_path": str(tmp_path / "uv.obj"),
    }
    res = {"subdivisions": 1, "layers": 1, "refine_radius": 0.03, "order": 1}
    with pytest.raises(ValueError, match="beta_2"):
        read_config(_cfg(body=body, bodies={"betas": [[0.0]]}))
    with pytest.raises(ValueError, match="anny takes phenotypes"):
        read_config(_cfg(bodies={"betas": [[0.0, 1.0]]}))
    cfg = _cfg(
        name="smpl",
        body=body,
        resolution=res,
        forces=[0.05, 0.1],
        bodies={"betas": [[0.0, -1.0], [0.0, 1.0]]},
        splits=[0.6, 0.2, 0.2],
        placements={"disk": {"centres": 6, "radii": [0.02]}},
    )
    card = generate(cfg, tmp_path / "smpl", progress=False)
    assert [m["thickness_mm"] for m in card["members"]] == [[6.25], [8.75]]
    path = train(
        {
            "name": "g",
            "model": "gnn",
            "data": str(tmp_path / "smpl"),
            "epochs": 2,
            "batch": 8,
            "out": str(tmp_path / "g"),
            "options": {
                "latent": 16,
                "steps": 2,
                "geometry": True,
                "prior": "linear",
                "operator": "on_demand",
                "per_newton": True,
                "loss": "relative",
            },
        },
        progress=False,
    )
    p = predictor.read(path)
    arm = part_from_spec({**body, "betas": [0.0, 0.4]}, "left_arm")
    at = int(np.argmin(np.abs(arm.axial - np.median(arm.axial))))
    scene = Scene(arm, tissue.from_beta2(arm, 0.4), loads.disk(arm, at, 0.02, 0.08).force)
    d = p.predict(scene)
    fem = FEMPredictor(res=res).predict(scene)
    m = sample_metrics(fem.displacement, d.displacement)
    assert m["rel_mee"] < 5.0 and abs(m["peak_err"]) < 10.0
