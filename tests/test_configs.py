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

    cfg = load_config(path)
    predictor._import_models()
    cls = predictor.REGISTRY[cfg["model"]]
    allowed = {**cls.defaults, "disp_scale_mm": None}
    assert set(cfg["options"]) <= set(allowed), set(cfg["options"]) - set(allowed)
    assert cfg["options"].get("loss", "mse") in predictor.LOSSES
