"""`stmpl ablate`: the config's checks, the tables, the cache (a rerun does nothing new), a
missing dataset made from its config.
"""

import json
import pathlib

import pytest

import stmpl.analysis.ablation as ablate
from stmpl.analysis import ablation_sets
from stmpl.cli.main import main


@pytest.fixture
def config(tiny_dataset, tmp_path, tiny_config):
    bands = tiny_config(
        name="tiny_bands",
        placements={"band": {"at": [0.3, 0.6], "widths": [0.03]}},
        splits=[0.0, 0.0, 1.0],
    )
    (tmp_path / "bands.yaml").write_text(json.dumps(bands))
    naive = {"model": "naive", "data": "unused", "epochs": 20, "batch": 16, "lr": 0.02}
    return {
        "name": "t",
        "datasets": {
            "tiny": {"folder": str(tiny_dataset)},
            "bands": {
                "config": str(tmp_path / "bands.yaml"),
                "folder": str(tmp_path / "data" / "bands"),
            },
        },
        "in_distribution": "tiny",
        "out_of_distribution": ["bands"],
        "seen_thickness_mm": [5.0],
        "setups": [
            {"name": "Naive", "train": naive},
            {"name": "Naive: only 5 mm", "train": naive, "thickness_mm": [5.0]},
            {"name": "FEM", "predictor": "fem", "limit": 2},
        ],
        "out": str(tmp_path / "report"),
        "runs": str(tmp_path / "runs"),
    }


def test_tables_rows_and_the_cache(config, tmp_path, monkeypatch):
    res = ablate.run(config, progress=False)
    t = res["tables"]
    assert list(t["table1"]) == ["Naive", "Naive: only 5 mm", "FEM"]
    assert set(t["table2"]) == {"Naive / bands", "Naive: only 5 mm / bands", "FEM / bands"}
    assert set(t["table3"]) == {
        f"Naive: only 5 mm / {w}, {s} thickness"
        for w in ("in-distribution", "bands")
        for s in ("seen", "unseen")
    }
    naive = t["table1"]["Naive"]
    assert 1.0 < naive["rel_mee"][0] < 100.0 and naive["samples"] > 0
    fem = t["table1"]["FEM"]
    assert fem["samples"] == 2 and fem["rel_mee"][0] < 50  # another mesh than the data's
    assert fem["seconds_per_scene"][0] > 10 * naive["seconds_per_scene"][0]
    seen = t["table3"]["Naive: only 5 mm / in-distribution, seen thickness"]["samples"]
    unseen = t["table3"]["Naive: only 5 mm / in-distribution, unseen thickness"]["samples"]
    assert seen + unseen == naive["samples"]
    md = (tmp_path / "report" / "ablation.md").read_text()
    assert "Table 1" in md and "*STMPL (paper)*" in md and "| Naive / bands |" in md
    # every planned test scene is counted, solved or not
    card = json.loads((tmp_path / "data" / "bands" / "card.json").read_text())
    bands = t["table2"]["Naive / bands"]
    planned = card["samples_per_split"]["test"] + card["failures_per_split"]["test"]
    assert bands["samples"] + bands["unsolved"] == planned
    assert "What the answers say about themselves" in md
    assert (tmp_path / "report" / "speed_accuracy.png").stat().st_size > 20_000
    assert (tmp_path / "report" / "speed_accuracy.svg").is_file()
    pts = {(p["label"], p["batch"]): p for p in res["points"]}
    assert ("Naive", 1) in pts and ("FEM", 1) in pts and ("FEM", 6) not in pts
    assert pts[("FEM", 1)]["seconds"] > 100 * pts[("Naive", 1)]["seconds"]
    naive = pts[("Naive", 1)]
    assert naive["out"]["rel_mee"] == pytest.approx(t["table2"]["Naive / bands"]["rel_mee"][0])
    assert naive["in"]["rel_mee"] == pytest.approx(t["table1"]["Naive"]["rel_mee"][0])
    # the 95 % interval of the mean over the test scenes, and the time's quartiles
    n, std = t["table1"]["Naive"]["samples"], t["table1"]["Naive"]["rel_mee"][1]
    assert naive["in"]["ci"] == pytest.approx(1.96 * std / n**0.5)
    low, high = naive["spread"]
    assert low <= naive["seconds"] <= high
    csv = (tmp_path / "report" / "table2.csv").read_text().splitlines()
    assert csv[0].startswith("setup,samples,mae_x_mean") and len(csv) == 1 + 3 + 3

    def boom(*a, **k):
        raise AssertionError("a cached job ran again")

    monkeypatch.setattr("stmpl.analysis.ablation.evaluate_dataset", boom)
    monkeypatch.setattr("stmpl.analysis.ablation.train", boom)
    again = ablate.run(config, progress=False)
    assert json.dumps(again["tables"], sort_keys=True) == json.dumps(t, sort_keys=True)


def test_a_setup_off_the_chart_stays_in_the_tables(config, monkeypatch):
    """``chart: false``: measured and tabled (its latency too), but not drawn on the chart; the
    chart is drawn at the last set-up, and after others only once ``CHART_EVERY`` has passed.
    """
    drawn = []
    monkeypatch.setattr(
        "stmpl.analysis.report.speed_accuracy",
        lambda pts, *a, **k: drawn.append({p["label"] for p in pts}),
    )
    config["setups"][1]["chart"] = False
    config["setups"] = config["setups"][:2]
    monkeypatch.setattr(ablate, "CHART_EVERY", 1e9)  # the chart once, at the last set-up
    res = ablate.run(config, progress=False)
    assert "Naive: only 5 mm" in res["tables"]["table1"]
    assert {p["label"] for p in res["points"]} == {"Naive", "Naive: only 5 mm"}
    assert drawn == [{"Naive"}]
    monkeypatch.setattr(ablate, "CHART_EVERY", 0.0)  # a slow run: after every set-up
    config["setups"][0]["epochs"] = 5  # (a new run, not the cache's)
    drawn.clear()
    ablate.run(config, progress=False)
    assert drawn == [{"Naive"}, {"Naive"}]


def test_the_truth_is_timed_and_drawn_but_not_measured(config, monkeypatch):
    """``truth: true`` (the FEM at the data's own mesh): no table row, a chart point on the
    floor with its time's quartiles.
    """
    drawn = []
    monkeypatch.setattr(
        "stmpl.analysis.report.speed_accuracy", lambda pts, *a, **k: drawn.append(pts)
    )
    config["setups"] = [config["setups"][0], {**config["setups"][2], "truth": True}]
    res = ablate.run(config, progress=False)
    assert "FEM" not in res["tables"]["table1"] and not res["tables"]["table3"]
    (truth,) = [p for p in drawn[-1] if p["label"] == "FEM"]
    assert truth["truth"] and truth["in"] is None and truth["out"] is None
    assert truth["spread"][0] <= truth["seconds"] <= truth["spread"][1]
    md = (pathlib.Path(config["out"]) / "ablation.md").read_text()
    assert "| FEM | 1 |" in md and "the truth" in md


def test_a_setup_of_several_seeds_trains_each_and_tables_them_together(config, tmp_path):
    """``seeds``: one training run per seed (their own run folders), each measured; the row is
    their answers together (the scenes counted once, the seeds' relative MEEs beside), the
    pooled out-of-distribution row pooled seed by seed; the report says how many seeds and
    their spread.
    """
    naive = {**config["setups"][0]["train"], "epochs": 5}
    config["out_of_distribution"] = ["bands", "bands2"]
    config["datasets"]["bands2"] = config["datasets"]["bands"]
    config["setups"] = [
        {"name": "Naive", "train": naive},
        {"name": "Naive x3", "train": naive, "seeds": [0, 1, 2]},
    ]
    res = ablate.run(config, progress=False)
    runs = sorted(p.name for p in (tmp_path / "runs").iterdir())
    assert len([r for r in runs if r.startswith("naive_x3-")]) == 3
    plain = [r.split("-")[1] for r in runs if r.startswith("naive-")]
    assert plain and f"naive_x3-{plain[0]}" in runs  # seed 0: the plain recipe's config
    one, three = res["tables"]["table1"]["Naive"], res["tables"]["table1"]["Naive x3"]
    assert three["samples"] == one["samples"] and three["seeds"]["count"] == 3
    seeds = three["seeds"]["rel_mee"]
    assert seeds[0] == pytest.approx(one["rel_mee"][0])  # seed 0 trains as the plain recipe
    assert len(set(seeds)) == 3  # other seeds, other networks
    assert min(seeds) <= three["rel_mee"][0] <= max(seeds)
    pooled = res["tables"]["table2"][f"Naive x3 / {ablate.POOLED}"]
    bands = res["tables"]["table2"]["Naive x3 / bands"]
    assert pooled["seeds"]["count"] == 3 and pooled["samples"] == 2 * bands["samples"]
    assert pooled["rel_mee"][0] == pytest.approx(bands["rel_mee"][0])  # the same set twice
    md = (tmp_path / "report" / "ablation.md").read_text()
    assert f"x 3 seeds (rel. MEE {min(seeds):.2f}-{max(seeds):.2f} %)" in md
    with pytest.raises(ValueError, match="seeds must list two or more"):
        ablate.read_config({**config, "setups": [{**config["setups"][1], "seeds": [1]}]})
    with pytest.raises(ValueError, match="for a trained set-up"):
        ablate.read_config(
            {**config, "setups": [{"name": "F", "predictor": "fem", "seeds": [0, 1]}]}
        )


def test_a_changed_setup_reruns_only_itself(config, monkeypatch):
    ablate.run(config, progress=False)
    calls = []
    from stmpl.pipeline import evaluate

    real = evaluate.evaluate_dataset

    def counted(p, ds, *a, **k):
        if "batch" in k:  # the runner's (training measures val/test too)
            calls.append(ds.card["name"])
        return real(p, ds, *a, **k)

    monkeypatch.setattr("stmpl.analysis.ablation.evaluate_dataset", counted)
    config["setups"][0]["epochs"] = 5  # only the first set-up changes
    ablate.run(config, progress=False)
    assert sorted(calls) == ["tiny", "tiny_bands"]


def test_a_cached_run_needs_no_data_and_makes_it_again_only_for_new_jobs(
    config, tmp_path, monkeypatch
):
    """Datasets take hours to make and a machine may lose them: a rerun whose jobs are all
    cached reads the cards it recorded instead of making the data again; a new job makes the
    missing dataset from its config, and it must come out the same.
    """
    import shutil

    first = ablate.run(config, progress=False)
    shutil.rmtree(tmp_path / "data" / "bands")

    def boom(*a, **k):
        raise AssertionError("a dataset was made again for cached jobs")

    monkeypatch.setattr("stmpl.analysis.ablation_sets._make", boom)
    again = ablate.run(config, progress=False)
    assert json.dumps(again["tables"], sort_keys=True) == json.dumps(
        first["tables"], sort_keys=True
    )
    assert not (tmp_path / "data" / "bands").exists()
    monkeypatch.undo()
    naive = next((tmp_path / "runs").glob("naive-*/*.safetensors"))
    config["setups"].append({"name": "Naive (auto)", "predictor": str(naive), "fidelity": "auto"})
    third = ablate.run(config, progress=False)
    assert (tmp_path / "data" / "bands" / "card.json").is_file()  # made for the new job
    assert "Naive (auto) / bands" in third["tables"]["table2"]
    cache = json.loads((tmp_path / "report" / "cache.json").read_text())
    assert (
        cache["datasets"]["bands"]["card"]["hash"]
        == json.loads((tmp_path / "data" / "bands" / "card.json").read_text())["hash"]
    )


def _remake(config, tmp_path, monkeypatch, scale: float) -> None:
    """Make the bands set again, every displacement scaled by ``scale`` (a remade set whose
    solver rounded differently, or one that differs).
    """
    import shutil

    import numpy as np

    from fem import backends

    real = backends.solve_shard

    def solve(payload):
        out = real(payload)
        out["records"]["displacement"] = [
            np.float32(scale) * u for u in out["records"]["displacement"]
        ]
        return out

    shutil.rmtree(tmp_path / "data" / "bands")
    with monkeypatch.context() as m:
        m.setattr(backends, "solve_shard", solve)
        ablation_sets._make("bands", config["datasets"]["bands"], False)


def test_a_dataset_made_again_stands_for_the_recorded_one_only_if_it_measures_the_same(
    config, tmp_path, monkeypatch
):
    """A lost dataset made again may differ in its last bits (its content hash changes): it is
    refused by name; with ``accept_remade`` a cached set-up is measured on it, and only if it
    measures the same do the cached results stand (nothing else runs again); one that differs
    more is refused.
    """
    import json as _json

    ablate.run(config, progress=False)
    naive = next((tmp_path / "runs").glob("naive-*/*.safetensors"))
    config["setups"].insert(0, {"name": "Naive as it is", "predictor": str(naive)})
    first = ablate.run(config, progress=False)
    recorded = _json.loads((tmp_path / "report" / "cache.json").read_text())
    old_hash = recorded["datasets"]["bands"]["card"]["hash"]

    _remake(config, tmp_path, monkeypatch, 1.000001)
    new_hash = _json.loads((tmp_path / "data" / "bands" / "card.json").read_text())["hash"]
    assert new_hash != old_hash
    with pytest.raises(
        ValueError, match=f"bands .* has hash {new_hash}, not the {old_hash}.*--accept-remade"
    ):
        ablate.run(config, progress=False)

    from stmpl.pipeline import evaluate

    real, calls = evaluate.evaluate_dataset, []

    def counted(p, ds, *a, **k):
        calls.append(ds.card["hash"])
        return real(p, ds, *a, **k)

    monkeypatch.setattr("stmpl.analysis.ablation.evaluate_dataset", counted)
    monkeypatch.setattr(
        "stmpl.analysis.ablation.train", lambda *a, **k: pytest.fail("trained again")
    )
    again = ablate.run(config, progress=False, accept_remade=True)
    assert calls == [new_hash]  # the check alone, on the remade set
    assert _json.dumps(again["tables"], sort_keys=True) == _json.dumps(
        first["tables"], sort_keys=True
    )
    cache = _json.loads((tmp_path / "report" / "cache.json").read_text())
    verdict = cache["datasets"]["bands"]["remade"]
    assert verdict["hash"] == new_hash and verdict["checked_with"] == "Naive as it is"
    assert abs(verdict["rel_mee"][1] - verdict["rel_mee"][0]) < 1e-3
    assert cache["datasets"]["bands"]["card"]["hash"] == old_hash
    assert "bands was made again" in (tmp_path / "report" / "ablation.md").read_text()
    ablate.run(config, progress=False, accept_remade=True)
    assert calls == [new_hash]  # checked once

    _remake(config, tmp_path, monkeypatch, 1.1)  # 10 % deeper: not the same set
    with pytest.raises(
        ValueError, match="bands made again measures differently: Naive as it is on it"
    ):
        ablate.run(config, progress=False, accept_remade=True)


@pytest.mark.parametrize(
    "change,message",
    [
        ({"in_distribution": "nope"}, "in_distribution must be one of"),
        ({"out_of_distribution": ["nope"]}, "out_of_distribution must list"),
        ({"setups": []}, "at least one set-up"),
        ({"setups": [{"name": "x"}]}, "either train"),
        (
            {"setups": [{"name": "x", "predictor": "fem"}, {"name": "x", "predictor": "fem"}]},
            "used twice",
        ),
        ({"setups": [{"name": "x", "predictor": "fem", "colour": 1}]}, "takes keys"),
        ({"setups": [{"name": "x", "predictor": "fem", "fidelity": "half"}]}, "full or auto"),
        ({"setups": [{"name": "x", "predictor": "fem", "chart": "no"}]}, "chart must be true or"),
        ({"setups": [{"name": "x", "predictor": "fem", "truth": 1}]}, "truth must be true or"),
        ({"datasets": {}}, "at least one dataset"),
    ],
)
def test_bad_configs_are_named(config, change, message):
    with pytest.raises(ValueError, match=message):
        ablate.read_config({**config, **change})


def test_cli_ablate(config, tmp_path, capsys):
    import yaml

    path = tmp_path / "a.yaml"
    path.write_text(yaml.safe_dump(config))
    assert main(["ablate", str(path), "--quiet"]) == 0
    assert "ablation.md" in capsys.readouterr().out
    assert main(["ablate", str(tmp_path / "missing.yaml")]) == 2
    assert "ablation config file not found" in capsys.readouterr().err
