"""Dataset generation: config checks, splits, failures, resuming after a kill, Dask workers."""

import json
import os
import re
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
import yaml

from fem.config import read_config
from fem.generate import generate, schedule
from fem.placements import Plan, plan, split_of
from fem.simulate import simulate
from stmpl.data.dataset import Dataset


def _cfg(**over):
    cfg = {
        "name": "tiny",
        "body": {"model": "tube", "radius": 0.04, "length": 0.2, "n_around": 16, "n_along": 12},
        "part": "tube",
        "thickness_mm": [5.0, 10.0],
        "resolution": {"subdivisions": 1, "layers": 2, "refine_radius": 0.03},
        "forces": [0.05, 0.1, 0.2],
        "placements": {
            "disk": {"centres": 4, "radii": [0.02]},
            "band": {"at": [0.5], "widths": [0.03]},
        },
        "shard_tasks": 2,
        "parallel": {"backend": "serial", "workers": 1},
    }
    cfg.update(over)
    return cfg


def _samples(folder):
    a = Dataset(folder).arrays()
    order = np.lexsort((a["total"], a["task"]))
    return {k: a[k][order] for k in ("task", "total", "displacement", "split")}


def _same(a, b):
    """Same samples; displacements equal to 1 nm (PARDISO's threads may round differently)."""
    for k in ("task", "total", "split"):
        np.testing.assert_array_equal(a[k], b[k])
    np.testing.assert_allclose(a["displacement"], b["displacement"], rtol=0, atol=1e-9)


def test_config_is_checked():
    with pytest.raises(ValueError, match="unknown dataset config keys"):
        read_config({**_cfg(), "forcez": [1.0]})
    with pytest.raises(ValueError, match="thickness_mm"):
        read_config(_cfg(thickness_mm=[50.0]))
    with pytest.raises(ValueError, match="forces"):
        read_config(_cfg(forces=[1.0, 0.5]))
    with pytest.raises(ValueError, match="placement kind"):
        read_config(_cfg(placements={"poke": {}}))
    with pytest.raises(ValueError, match="placements.disk takes keys"):
        read_config(_cfg(placements={"disk": {"centers": 3}}))
    with pytest.raises(ValueError, match="resolution"):
        read_config(_cfg(resolution="ultra"))
    with pytest.raises(FileNotFoundError):
        read_config("no/such/config.yaml")
    cfg = read_config(_cfg(placements={"band": {"at": [1.5]}}))
    with pytest.raises(ValueError, match="impossible load placement band"):
        plan(cfg)


def test_splits_go_by_placement():
    s = split_of(20, [0.8, 0.1, 0.1], seed=0)
    assert np.bincount(s, minlength=3).tolist() == [16, 2, 2]
    assert np.bincount(split_of(5, [0.8, 0.1, 0.1], 0), minlength=3).tolist() == [3, 1, 1]
    assert not np.array_equal(split_of(20, [0.8, 0.1, 0.1], 1), s)


def test_shards_begun_go_first_then_every_split_at_its_share():
    split = split_of(12, [0.5, 0.25, 0.25], seed=0)  # 6 training, 3 validation, 3 test places
    p = Plan({"shard_tasks": 1}, None, [{}] * 12, split, [(i, 0) for i in range(12)])
    order = schedule(p, list(range(12)), begun={7, 2})
    assert sorted(order) == list(range(12)) and order[:2] == [2, 7]
    rest = split[order[2:]]
    share = np.bincount(rest, minlength=3) / len(rest)
    for n in range(1, 11):  # every prefix of the rest holds each split at its share, +- 1
        assert np.all(np.abs(np.bincount(rest[:n], minlength=3) - n * share) <= 1), n
    for s_ in range(3):  # each split's shards in their own order
        mine = [k for k in order[2:] if split[k] == s_]
        assert mine == sorted(mine)


def test_serial_run_card_and_samples(tmp_path):
    card = generate(_cfg(), tmp_path / "d", progress=False)
    p = plan(read_config(_cfg()))
    assert card["placements"] == 5 and card["tasks"] == 10
    assert card["samples"] + card["failures"] == card["attempted"] == 30
    assert card["samples"] == sum(card["samples_per_split"].values())
    ds = Dataset(tmp_path / "d")
    ds.verify()
    a = ds.arrays()
    # every placement's samples share one split
    for pl in np.unique(a["placement"]):
        assert len(np.unique(a["split"][a["placement"] == pl])) == 1
    assert set(ds.arrays("val")["placement"]).isdisjoint(ds.arrays("train")["placement"])
    # a stored sample is the solver's answer for that load
    i = [j for j, k in enumerate(a["kind"]) if k == "disk"][2]
    pl = p.placements[a["placement"][i]]
    from fem.placements import make_load

    load = make_load(ds.part, pl)
    th = a["thickness"][i].astype(float)
    levels = [f for f in _cfg()["forces"] if f <= a["total"][i]]
    mesh, sols = simulate(ds.part, th, load.force, levels, _cfg()["resolution"])
    np.testing.assert_allclose(a["displacement"][i], sols[-1].part_displacement(mesh), atol=1e-7)
    np.testing.assert_allclose(a["force"][i].sum(), a["total"][i], rtol=1e-5)
    assert json.loads((tmp_path / "d" / "card.json").read_text())["hash"] == card["hash"]


def test_failures_are_counted_and_kept_apart_from_the_samples(tmp_path):
    cfg = _cfg(
        thickness_mm=[5.0],
        forces=[0.1, 3.0, 4.0],
        max_pressure=3000.0,
        placements={"disk": {"centres": 2, "radii": [0.02]}},
    )
    card = generate(cfg, tmp_path / "f", progress=False)
    assert card["failures"] > 0 and card["samples"] + card["failures"] == card["attempted"]
    assert card["failures_by_reason"]
    assert sum(card["failures_per_split"].values()) == card["failures"]
    ds = Dataset(tmp_path / "f")
    a = ds.arrays()
    assert np.all(a["max_compression"] <= 1.0)
    assert np.all(np.isfinite(a["displacement"]))
    # every failure keeps its inputs: the load the sample would have had, on its split
    f = ds.failed()
    assert len(f["total"]) == card["failures"] == len(f["reason"])
    np.testing.assert_allclose(f["force"].sum(1), f["total"], rtol=1e-5)
    np.testing.assert_allclose(f["thickness"], 5e-3, rtol=1e-6)
    for s, n in card["failures_per_split"].items():
        assert len(ds.failed(s)["total"]) == n
    placed = {int(t): int(s) for t, s in zip(a["task"], a["split"])}
    assert all(placed.get(r["task"], r["split"]) == r["split"] for r in _failure_records(ds))


def _failure_records(ds):
    import h5py

    out = []
    for s in ds.shards:
        with h5py.File(s, "r") as h:
            out += json.loads(h.attrs["failures"])
    return out


def test_an_edited_failure_is_refused(tmp_path):
    import h5py

    cfg = _cfg(
        thickness_mm=[5.0],
        forces=[0.1, 4.0],
        max_pressure=3000.0,
        placements={"disk": {"centres": 2, "radii": [0.02]}},
    )
    generate(cfg, tmp_path / "f", progress=False)
    ds = Dataset(tmp_path / "f")
    shard = ds.shards[_failure_records(ds)[0]["task"] // cfg["shard_tasks"]]
    with h5py.File(shard, "a") as h:
        h["failed_force"][0, 0] += 1.0
    with pytest.raises(ValueError, match="failed samples were changed after it was written"):
        Dataset(tmp_path / "f").failed()


def test_a_killed_run_resumes_without_loss_or_duplicates(tmp_path):
    cfg = _cfg(shard_tasks=1, resolution={"subdivisions": 2, "layers": 2, "refine_radius": 0.03})
    path = tmp_path / "cfg.yaml"
    path.write_text(yaml.safe_dump(cfg))
    out = tmp_path / "killed"
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "stmpl.cli.main",
            "generate",
            str(path),
            "--out",
            str(out),
            "--quiet",
        ],
        env={**os.environ},
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    deadline = time.time() + 120
    while time.time() < deadline and not list(out.glob("shard-*.h5")):
        time.sleep(0.05)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    done = len(list(out.glob("shard-*.h5")))
    assert 1 <= done < 10, done
    assert not (out / "card.json").exists()
    (out / "shard-00009.h5.x.tmp").write_bytes(b"half a file")  # a torn write
    generate(path, out, progress=False)
    assert not list(out.glob("*.tmp")) and not list(out.glob("*.progress.pkl"))
    resumed = json.loads((out / "card.json").read_text())
    whole = generate(cfg, tmp_path / "whole", progress=False)
    a, b = _samples(out), _samples(tmp_path / "whole")
    assert len(np.unique(np.stack([a["task"], a["total"]], 1), axis=0)) == len(a["task"])
    _same(a, b)
    if all(np.array_equal(a[k], b[k]) for k in a):  # bit-identical samples: one hash
        assert resumed["hash"] == whole["hash"]
    # the same folder refuses a different config, and a second run while one writes it
    with pytest.raises(ValueError, match="different config"):
        generate(_cfg(forces=[0.05]), out, progress=False)
    (out / ".lock").write_text(f"{os.getppid()} stmpl generate\n")
    with pytest.raises(RuntimeError, match="held by stmpl generate"):
        generate(path, out, progress=False)


def test_dask_local_cluster_with_two_workers_matches_serial(tmp_path):
    pytest.importorskip("dask.distributed")
    cfg = _cfg(thickness_mm=[7.5])
    generate(cfg, tmp_path / "serial", progress=False)
    generate(cfg, tmp_path / "dask", backend="dask", workers=2, progress=False)
    a, b = _samples(tmp_path / "serial"), _samples(tmp_path / "dask")
    _same(a, b)


def test_cli_generate_stops_early_and_finishes(tmp_path, capsys, monkeypatch):
    from stmpl.cli.main import main

    path = tmp_path / "cfg.yaml"
    path.write_text(yaml.safe_dump(_cfg(thickness_mm=[7.5], forces=[0.05, 0.1])))
    out = tmp_path / "cli"
    assert main(["generate", str(path), "--out", str(out), "--max-shards", "0"]) == 2
    assert "no finished shard yet" in capsys.readouterr().err
    assert main(["generate", str(path), "--out", str(out), "--max-shards", "1"]) == 0
    said = capsys.readouterr()
    assert "stopped early: 1 of " in said.out
    # the bar runs from nothing to this run's shard, not to the whole set
    bar = re.findall(r"(\d+)/(\d+) \[", said.err)
    assert bar[0][0] == "0" and bar[-1][0] == bar[-1][1]
    assert len(list(out.glob("shard-*.h5"))) == 1
    # a set part way has a card of what it holds, and is read (and trained on) as such
    part_way = json.loads((out / "card.json").read_text())
    assert not part_way["complete"] and part_way["tasks"] < part_way["tasks_planned"]
    ds = Dataset(out)
    assert not ds.complete and "part way" in repr(ds)
    assert (
        len(ds.arrays()["task"])
        == part_way["samples"]
        == part_way["attempted"] - part_way["failures"]
    )
    # a run that solves nothing cards the set once more, and draws no bar
    assert main(["generate", str(path), "--out", str(out), "--max-shards", "0"]) == 0
    said = capsys.readouterr()
    assert "stopped early: 1 of " in said.out and not re.findall(r"\d+/\d+ \[", said.err)
    assert json.loads((out / "card.json").read_text())["tasks"] == part_way["tasks"]
    from fem import generate as gen

    build = {"git": "the build the run started on"}
    monkeypatch.setattr(gen, "code_version", lambda: {"stmpl": "0.1.0", **build})
    write = gen.write_shard

    def moved_on(*args, **kwargs):  # the checkout moves on while the run goes
        build["git"] = "a later build"
        return write(*args, **kwargs)

    monkeypatch.setattr(gen, "write_shard", moved_on)
    assert main(["generate", str(path), "--out", str(out), "--quiet"]) == 0
    printed = capsys.readouterr().out
    card = json.loads((out / "card.json").read_text())
    assert f"{card['samples']} samples" in printed and "stopped early" not in printed
    assert card["complete"] and Dataset(out).complete
    assert card["tasks"] == card["tasks_planned"] and card["attempted"] == card["planned"]
    runs = card["timing"]["runs"]
    assert len(runs) == 2 and runs[0]["shards"] == len(runs[0]["written"]) == 1
    shards = len(list(out.glob("shard-*.h5")))
    assert sorted(runs[0]["written"] + runs[1]["written"]) == list(range(shards))
    assert all(r["code"]["stmpl"] for r in runs)  # which build solved which shards
    assert runs[1]["code"]["git"] == "the build the run started on"
    assert card["attempted"] > int(bar[-1][1])
    assert main(["generate", str(tmp_path / "missing.yaml")]) == 2
    assert "config file not found" in capsys.readouterr().err


def test_workers_leave_when_the_generator_is_killed(tmp_path):
    psutil = pytest.importorskip("psutil")
    cfg = _cfg(
        shard_tasks=1,
        parallel={"backend": "processes", "workers": 2},
        resolution={"subdivisions": 2, "layers": 2, "refine_radius": 0.03},
    )
    path = tmp_path / "cfg.yaml"
    path.write_text(yaml.safe_dump(cfg))
    out = tmp_path / "orphans"
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "stmpl.cli.main",
            "generate",
            str(path),
            "--out",
            str(out),
            "--quiet",
        ],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    parent = psutil.Process(proc.pid)
    deadline = time.time() + 120

    def spawned():
        out_ = []
        for c in parent.children(recursive=True):
            try:
                if "spawn_main" in " ".join(c.cmdline()):
                    out_.append(c)
            except psutil.Error:  # a process that ended meanwhile
                pass
        return out_

    workers = []
    while time.time() < deadline and not list(out.glob("shard-*.h5")):
        workers = spawned() or workers
        time.sleep(0.05)
    assert workers, "no worker processes seen"
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    gone, alive = psutil.wait_procs(workers, timeout=10)
    assert not alive, [p.pid for p in alive]


def test_sigterm_stops_generate_in_one_line_and_leaves_no_temporary_file(tmp_path):
    psutil = pytest.importorskip("psutil")
    cfg = _cfg(shard_tasks=1, parallel={"backend": "processes", "workers": 2})
    cfg["placements"]["disk"]["centres"] = 24  # far more work than the first shard's time
    path = tmp_path / "cfg.yaml"
    path.write_text(yaml.safe_dump(cfg))
    out = tmp_path / "stopped"
    argv = [sys.executable, "-m", "stmpl.cli.main", "generate", str(path), "--out", str(out)]
    proc = subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    parent = psutil.Process(proc.pid)
    deadline = time.time() + 120
    while time.time() < deadline and not list(out.glob("shard-*.h5")):
        time.sleep(0.05)
    workers = parent.children(recursive=True)
    proc.send_signal(signal.SIGTERM)
    err = proc.communicate(timeout=60)[1]
    assert proc.returncode == 143, err
    assert "stmpl generate: stopped by SIGTERM; what was finished is kept" in err
    assert "Traceback" not in err
    _, alive = psutil.wait_procs(workers, timeout=10)
    assert not alive and not list(out.glob("*.tmp"))


def test_fidelity_auto_solves_patches_within_a_percent_of_the_whole(tmp_path):
    """The same plan solved whole and on patches (fem.local): the same samples, displacements
    within 1 % of each sample's largest; the config hash of the default (full) is the one
    configs had before the key existed.
    """
    from fem.config import config_hash

    body = {"model": "tube", "radius": 0.04, "length": 0.4, "n_around": 24, "n_along": 30}
    over = dict(
        body=body, placements={"disk": {"centres": 3, "radii": [0.015]}}, thickness_mm=[7.5]
    )
    generate(_cfg(**over), tmp_path / "full", progress=False)
    generate(_cfg(**over, fidelity="auto"), tmp_path / "auto", progress=False)
    a, b = _samples(tmp_path / "full"), _samples(tmp_path / "auto")
    assert len(a["total"]) == len(b["total"]) > 0
    np.testing.assert_array_equal(a["total"], b["total"])
    peak = np.linalg.norm(a["displacement"], axis=2).max(1)
    err = np.linalg.norm(a["displacement"] - b["displacement"], axis=2).max(1)
    assert np.all(err < 0.01 * peak)
    assert Dataset(tmp_path / "auto").card["config"]["fidelity"] == "auto"
    full = read_config(_cfg())
    assert config_hash(full) == config_hash({k: v for k, v in full.items() if k != "fidelity"})
    assert config_hash(read_config(_cfg(fidelity="auto"))) != config_hash(full)
    with pytest.raises(ValueError, match="fidelity must be one of"):
        read_config(_cfg(fidelity="local"))


def test_a_layered_tissue_dataset_holds_the_presets_answers(tmp_path):
    """``tissue: forearm`` (or ``stmpl generate --tissue forearm``): each sample is what the
    layered FEM answers, and the card keeps the preset.
    """
    cfg = _cfg(
        thickness_mm=[7.5],
        forces=[0.5, 1.0],
        max_pressure=1e6,
        resolution={"subdivisions": 1, "layers": 2, "refine_radius": 0.03, "order": 2},
        placements={"disk": {"centres": 1, "radii": [0.02]}},
    )
    card = generate(cfg, tmp_path / "d", progress=False, tissue="forearm")
    assert card["config"]["tissue"] == "forearm" and card["samples"] == 2, card[
        "failures_by_reason"
    ]
    ds = Dataset(tmp_path / "d")
    a = ds.arrays()
    from fem.placements import make_load

    load = make_load(ds.part, plan(read_config(cfg)).placements[0])
    th = a["thickness"][0].astype(float)
    mesh, sols = simulate(ds.part, th, load.force, [0.5, 1.0], cfg["resolution"], tissue="forearm")
    i = int(np.argmax(a["total"]))
    np.testing.assert_allclose(a["displacement"][i], sols[-1].part_displacement(mesh), atol=1e-7)


@pytest.mark.parametrize(
    "over, message",
    [
        ({"tissue": "bone"}, "unknown tissue preset 'bone'"),
        ({"tissue": 3}, "tissue must be a preset name or a mapping"),
        ({"tissue": "forearm", "material": {"name": "neo_hookean", "E": 2000.0}}, "own laws"),
        ({"tissue": "forearm", "linear": True}, "linear FEM of the layered"),
        (
            {"tissue": "forearm", "resolution": {"subdivisions": 1, "layers": 2, "order": 1}},
            "forearm tissue's nearly incompressible layers lock in linear",
        ),
    ],
)
def test_a_bad_tissue_is_named(over, message):
    with pytest.raises(ValueError, match=message):
        read_config(_cfg(**over))


def test_a_dataset_of_pressed_objects_holds_force_controlled_answers(tiny_presses):
    """``press_sphere`` and ``press_disk`` placements: each object is pushed by force control
    to every force level into the layered tissue, and each answer is a sample: its per-vertex
    contact forces sum to the contact's total (within force control's 1 % of the level), its
    pressure map and its pose (``gap``: the rest skin's distance to the object, negative where
    the object reaches in) come with it, the same as one press solved alone, and the card
    names the tissue and the force range.
    """
    from fem.force_control import press_to_force
    from fem.objects import placed
    from fem.simulate import resolution, tissue_mesh
    from fem.solver import Solver

    ds = Dataset(tiny_presses)
    card, cfg = ds.card, ds.card["config"]
    assert card["samples"] == 3, card["failures_by_reason"]
    assert card["tissue"] == "forearm" and card["force_range_N"] == [0.3, 0.3]
    a = ds.arrays()
    params = a["params"]
    assert sorted(a["kind"]) == ["press_disk", "press_sphere", "press_sphere"]
    for i in range(3):
        assert params[i]["reaction"] == pytest.approx(a["total"][i], rel=0.011)
        assert a["force"][i].sum() == pytest.approx(a["total"][i], rel=0.05)
        np.testing.assert_allclose(
            a["force"][i], a["pressure"][i] * ds.part.vertex_areas, rtol=1e-5
        )
        pushed = float(np.sum(a["push"][i] * ds.part.vertex_areas))
        assert pushed == pytest.approx(params[i]["reaction"], rel=1e-5)  # the reaction's density
        touched = a["pressure"][i] > 0
        assert a["gap"][i][touched].min() < 0 < a["gap"][i].max()
        assert params[i]["depth"] > 0
    sphere = next(i for i in range(3) if a["kind"][i] == "press_sphere")
    shape, direction = placed(ds.part, "press_sphere", params[sphere])
    th = a["thickness"][sphere].astype(float)
    at = ds.part.vertices[[params[sphere]["at"]]]
    mesh, mat = tissue_mesh(ds.part, th, cfg["resolution"], "forearm", None, near=at)
    solver = Solver(mesh, mat, order=resolution(cfg["resolution"]).order)
    alone = press_to_force(solver, shape, direction, 0.3)
    np.testing.assert_allclose(a["displacement"][sphere], alone.displacement, atol=1e-7)


def test_a_dataset_of_grips_holds_the_hand_s_squeeze_and_pose(tmp_path):
    """``press_grip``: anny's pinch closing on a tube by force control, with Coulomb's friction.
    Its sample's force is the squeeze (the contact forces summed, within force control's 1 %),
    its push the pressure itself, its pose the rest skin's distance to the hand (cut as a
    scene's is) with no direction; a scene made from it is a closing pose; a friction the config
    cannot use is refused by name.
    """
    from stmpl.pipeline.evaluate import scenes_of
    from stmpl.pose import GAP_REACH

    body = {"model": "tube", "radius": 0.035, "length": 0.22, "n_around": 24, "n_along": 22}
    cfg = _cfg(
        body=body,
        thickness_mm=[7.5],
        forces=[0.05],
        resolution={"subdivisions": 0, "layers": 2, "refine_radius": 0.02, "order": 1},
        placements={"press_grip": {"along": [0.5], "grips": ["pinch"]}},
        splits=[0.0, 0.0, 1.0],
        friction=0.5,
    )
    generate(cfg, tmp_path / "grips", progress=False)
    ds = Dataset(tmp_path / "grips")
    assert ds.card["samples"] == 1, ds.card["failures_by_reason"]
    assert ds.card["config"]["friction"] == 0.5
    a = ds.arrays()
    params = a["params"][0]
    assert params["grip"] == "pinch" and params["direction"] is None and params["depth"] > 0
    assert params["reaction"] == pytest.approx(0.05, rel=0.011)
    assert a["force"][0].sum() == pytest.approx(params["reaction"], rel=1e-5)
    np.testing.assert_allclose(a["push"][0], a["pressure"][0])
    assert a["gap"][0].min() < 0 and a["gap"][0].max() == pytest.approx(GAP_REACH)
    (scene,), _ = scenes_of(ds, "test", given="pose")
    assert scene.pose.closing and not scene.pose.objects
    with pytest.raises(ValueError, match="only pressed objects"):
        read_config(_cfg(friction=0.5))
    with pytest.raises(ValueError, match="friction must be a number >= 0"):
        read_config(_cfg(placements={"press_grip": {"along": [0.5]}}, friction=-1))


def test_a_press_set_meets_its_forces_within_its_force_tolerance(tmp_path, monkeypatch):
    """A set's ``force_tolerance`` is what force control meets each force within (a training
    set for pose models, whose force levels only spread the squeezes, may take a wide one and
    spare the search's later tries); left at its default, the config's hash is the one from
    before the key existed.
    """
    import fem.worker
    from fem.config import config_hash
    from fem.contact import Pressed

    seen = []

    def stand_in(solver, shape, direction, forces, on_answer=None, rtol=0.01, **kw):
        seen.append(rtol)
        out = [Pressed(False, "stand-in", float("nan")) for _ in forces]
        for f, a in zip(forces, out):
            on_answer(f, a)
        return out

    monkeypatch.setattr(fem.worker, "press_to_forces", stand_in)
    over = {
        "placements": {"press_sphere": {"centres": 1, "radii": [0.008]}},
        "thickness_mm": [5.0],
        "forces": [0.05],
        "tissue": "forearm",
        "resolution": {"subdivisions": 0, "layers": 1, "refine_radius": 0.02, "order": 2},
    }
    generate(_cfg(force_tolerance=0.2, **over), tmp_path / "wide", progress=False)
    assert seen == [0.2]
    card = Dataset(tmp_path / "wide").card
    assert card["config"]["force_tolerance"] == 0.2 and card["failures_by_reason"] == {
        "stand-in": 1
    }
    default = read_config(_cfg(**over))
    assert config_hash(default) == config_hash(
        {k: v for k, v in default.items() if k != "force_tolerance"}
    )
    assert config_hash(read_config(_cfg(force_tolerance=0.2, **over))) != config_hash(default)


def test_pressed_objects_keep_clear_of_the_held_rims():
    """A press's centre keeps its radius plus twice the deepest tissue from the part's cut
    rims (held in place by the FEM), and a part too small for the centres asked is refused.
    """
    cfg = read_config(_cfg(placements={"press_disk": {"centres": 6, "radii": [0.01]}}))
    p = plan(cfg)
    rims = p.part.vertices[np.concatenate(p.part.rims)]
    at = p.part.vertices[[q["params"]["at"] for q in p.placements]]
    assert len(set(q["params"]["at"] for q in p.placements)) == 6
    assert np.linalg.norm(at[:, None] - rims[None], axis=2).min() >= 0.01 + 2 * 0.010
    with pytest.raises(ValueError, match="mm or more from its cut rims"):
        plan(read_config(_cfg(placements={"press_disk": {"centres": 6, "radii": [0.08]}})))


def test_presses_are_solved_on_the_whole_part():
    cfg = _cfg(placements={"press_sphere": {"centres": 1, "radii": [0.008]}}, fidelity="auto")
    with pytest.raises(ValueError, match="solved on the whole part"):
        read_config(cfg)
    with pytest.raises(ValueError, match="rounding"):
        read_config(_cfg(placements={"press_disk": {"centres": 1, "rounding": [1]}}))


@pytest.mark.parametrize("backend, workers", [("serial", 1), ("processes", 2)])
def test_every_planned_sample_ticks_the_progress_as_it_ends(backend, workers):
    """The progress bar counts planned samples, solved or failed, as they end inside a shard
    (a press's shard takes a quarter of an hour), in this process or from workers.
    """
    from fem.backends import run

    cfg = read_config(_cfg(forces=[0.05, 0.1, 50.0], max_pressure=1000.0))  # 50 N: over the cap
    p = plan(cfg)
    ticks = []
    par = {"backend": backend, "workers": workers, "scheduler": None}
    shards = list(run(p, list(range(p.n_shards)), par, 1, ticks.append))
    solved = sum(len(r["records"]["task"]) for r in shards)
    failed = sum(len(r["failures"]) for r in shards)
    assert failed >= len(p.tasks) and sum(ticks) == solved + failed == 3 * len(p.tasks)


def _killed(payload):
    """A worker's shard that ends the way an out-of-memory kill ends it: without a word."""
    os._exit(9)


def test_a_worker_that_dies_is_named_in_one_line_that_says_the_run_resumes(monkeypatch):
    from fem import backends

    monkeypatch.setattr(backends, "solve_shard", _killed)
    p = plan(read_config(_cfg()))
    par = {"backend": "processes", "workers": 2, "scheduler": None}
    with pytest.raises(backends.WorkerDied, match=r"died while solving shard\(s\) 0.*resumes") as e:
        list(backends.run(p, [0, 1], par, 1))
    assert e.value.shards and set(e.value.shards) <= {0, 1}
    assert isinstance(e.value, OSError)  # the command line's one-line failures


def test_a_worker_knows_the_part_a_subdivided_part_came_from():
    """So a press on it is meshed on the coarser part (fem.finer), in every worker process."""
    from fem.worker import part_of, payload

    body = {"model": "tube", "radius": 0.04, "length": 0.2, "n_around": 16, "n_along": 12}
    p = plan(read_config(_cfg(body={**body, "subdivisions": 1})))
    part = part_of(payload(p, 0, None))
    assert part.n_vertices == p.part.n_vertices and part.coarser is not None
    np.testing.assert_array_equal(part.coarser.vertices, p.part.coarser.vertices)
    np.testing.assert_array_equal(part.coarser.faces, p.part.coarser.faces)
    assert part.coarser.source == p.part.coarser.source
    assert part_of(payload(plan(read_config(_cfg())), 0, None)).coarser is None


class _Stop(Exception):
    pass


def test_a_press_shard_stopped_between_forces_takes_up_its_kept_progress(tmp_path):
    """A press task's forces take minutes each: a shard stopped after its first force keeps it,
    and solved again it answers only the rest, warm from the kept answer, the same samples as a
    shard never stopped to the solver's tolerance (a fresh solver keeps no factorisation to
    precondition with, so the last digits may differ: 4.5e-5 of the deepest seen), its resumed
    sample ticked once more.
    """
    from fem.worker import payload, solve_shard
    from tests.conftest import TINY_PRESSES

    cfg = read_config(
        {
            **TINY_PRESSES,
            "forces": [0.1, 0.2],
            "placements": {"press_sphere": {"centres": 1, "radii": [0.008]}},
        }
    )
    p = plan(cfg)
    keep = tmp_path / "shard-00000.progress.pkl"

    def stop(n):
        raise _Stop

    with pytest.raises(_Stop):
        solve_shard(payload(p, 0, None, stop, keep))
    assert keep.is_file()
    ticks = []
    resumed = solve_shard(payload(p, 0, None, ticks.append, keep))
    whole = solve_shard(payload(p, 0, None))
    assert ticks == [1, 1] and resumed["failures"] == whole["failures"] == []
    a, b = resumed["records"], whole["records"]
    np.testing.assert_array_equal(a["total"], b["total"])
    deepest = np.abs(np.stack(b["displacement"])).max()
    np.testing.assert_allclose(
        np.stack(a["displacement"]), np.stack(b["displacement"]), rtol=0, atol=1e-4 * deepest
    )
    assert [json.loads(q)["depth"] for q in a["params"]] == pytest.approx(
        [json.loads(q)["depth"] for q in b["params"]], rel=1e-4
    )


def test_kept_progress_of_another_config_is_named_and_not_taken_up(tmp_path, capsys):
    from fem.worker import payload, solve_shard

    p = plan(read_config(_cfg(forces=[0.05])))
    keep = tmp_path / "shard-00000.progress.pkl"
    keep.write_bytes(b"half a file")
    torn = solve_shard(payload(p, 0, None, None, keep))
    assert "not taken up" in capsys.readouterr().err
    whole = solve_shard(payload(p, 0, None))
    assert len(torn["records"]["task"]) == len(whole["records"]["task"]) > 0
    other = plan(read_config(_cfg(forces=[0.05, 0.1])))
    solve_shard(payload(other, 0, None, None, keep))
    assert "another config" in capsys.readouterr().err
