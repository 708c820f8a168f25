"""Every shipped config loads and passes its checks: data configs through the generator's
loader, training configs through the trainer's and their model options through the model's."""

import pathlib

import pytest

from stmpl import predictor

CONFIGS = pathlib.Path(__file__).resolve().parents[1] / "configs"


@pytest.mark.parametrize("path", sorted((CONFIGS / "data").glob("*.yaml")), ids=lambda p: p.name)
def test_data_configs_load(path):
    from fem.generate import load_config

    cfg = load_config(path)
    assert cfg["forces"] and cfg["thickness_mm"]


@pytest.mark.parametrize("path", sorted((CONFIGS / "train").glob("*.yaml")), ids=lambda p: p.name)
def test_training_configs_load(path):
    from stmpl.train import load_config

    cfg = load_config(path)  # checks the model options too (unknown keys, loss, scale)
    assert cfg["options"].get("loss", "mse") in predictor.LOSSES


def test_bad_model_options_fail_on_load():
    from stmpl.train import load_config

    with pytest.raises(ValueError, match="unknown gnn model options"):
        load_config({"model": "gnn", "data": "x", "options": {"width": 3}})
    with pytest.raises(ValueError, match="loss must be one of"):
        load_config({"model": "gnn", "data": "x", "options": {"loss": "l1"}})
