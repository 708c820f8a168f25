"""Every shipped config loads and passes its checks: data configs through the generator's
loader, training configs through the trainer's and their model options through the model's; and
every training config trains on a dataset a shipped data config makes.
"""

import pathlib

import pytest

CONFIGS = pathlib.Path(__file__).resolve().parents[1] / "configs"


@pytest.mark.parametrize("path", sorted((CONFIGS / "data").glob("*.yaml")), ids=lambda p: p.name)
def test_data_configs_load(path):
    from fem.config import read_config

    cfg = read_config(path)
    assert cfg["name"] == path.stem  # `stmpl generate` writes data/<stem>, as training expects


@pytest.mark.parametrize("path", sorted((CONFIGS / "train").glob("*.yaml")), ids=lambda p: p.name)
def test_training_configs_load(path):
    from stmpl.pipeline.train import read_config

    cfg = read_config(path)  # checks the model options too (unknown keys, loss, scale)
    for d in cfg["data"] if isinstance(cfg["data"], list) else [cfg["data"]]:
        data = pathlib.Path(d)  # each set a config of ours makes (or one of its bodies)
        if data.name.startswith("body-"):
            assert data.name[5:].isdigit()
            data = data.parent
        assert data.parent == pathlib.Path("data")
        assert (CONFIGS / "data" / f"{data.name}.yaml").is_file()


def test_bad_model_options_fail_on_load():
    from stmpl.pipeline.train import read_config

    with pytest.raises(ValueError, match="unknown gnn model options"):
        read_config({"model": "gnn", "data": "x", "options": {"width": 3}})
    with pytest.raises(ValueError, match="loss must be one of"):
        read_config({"model": "gnn", "data": "x", "options": {"loss": "l1"}})
    with pytest.raises(ValueError, match="steps must be an integer >= 1, got -2"):
        read_config({"model": "gnn", "data": "x", "options": {"steps": -2}})
    with pytest.raises(ValueError, match="width must be an integer >= 1, got '16'"):
        read_config({"model": "uv_unet", "data": "x", "options": {"width": "16"}})
    with pytest.raises(ValueError, match="disp_scale_mm must be a number"):
        read_config({"model": "gnn", "data": "x", "options": {"disp_scale_mm": "ten"}})


@pytest.mark.parametrize(
    "path", sorted((CONFIGS / "ablation").glob("*.yaml")), ids=lambda p: p.name
)
def test_ablation_configs_load(path):
    """Every dataset an ablation names has a shipped config writing where the ablation reads,
    and every set-up's training config loads.
    """
    import yaml

    from fem.config import read_config as read_data
    from stmpl.analysis.ablation import read_config
    from stmpl.pipeline.train import read_config as read_train

    if yaml.safe_load(path.read_text()).get("kind") == "stability":
        from stmpl.analysis import stability

        cfg = stability.read_config(path)
        assert cfg["out"] == f"reports/{cfg['name']}"
        for spec in cfg["predictors"]:  # every model it sweeps is shipped
            from stmpl.pipeline import zoo

            assert not spec.startswith("zoo:") or spec[4:] in zoo.names(), spec
        return
    cfg = read_config(path)
    root = CONFIGS.parent
    for d in cfg["datasets"].values():
        data = read_data(root / d["config"])
        assert pathlib.Path(d["folder"]) == pathlib.Path("data") / data["name"]
    for s in cfg["setups"]:
        if "train" in s:
            read_train(root / s["train"])
