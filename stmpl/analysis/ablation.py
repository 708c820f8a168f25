"""``stmpl ablate CONFIG``: the paper's Tables 1-3 for every predictor, on equal terms.

A config (``configs/ablation/*.yaml``) names the datasets (made from their dataset configs when
missing) and the set-ups: learned models trained from a training config (optionally on a subset
of thickness levels: the paper's "only 3 beta_2"), and predictors taken as they are (``fem:coarse``,
``zoo:gnn_arm``, a checkpoint). Every set-up is evaluated on the in-distribution test split
(Table 1), on each out-of-distribution set (Table 2) and, for set-ups trained on a subset of
thicknesses, on seen and unseen thicknesses in and out of distribution (Table 3). Columns: the
paper's (MAE x/y/z, MEE, shares of errors under 0.1-0.5 mm) and ours (relative MEE, peak error,
largest error, seam gap, time per scene, share inside the envelope). The paper's own rows are
printed beside ours, marked as reported.

Runs are cached: a training run lives in ``runs/<config name>/<set-up>-<hash>`` (the hash of its
resolved training config and the dataset's content hash; an interrupted run resumes), and every
evaluation is kept in ``<out>/cache.json`` under the hash of what decides it. A rerun does only
what changed.
"""

from __future__ import annotations

import copy
import hashlib
import json
import pathlib
import time
import warnings

import numpy as np
import yaml
from tqdm import tqdm

from stmpl import config as checked
from stmpl.analysis import stability
from stmpl.analysis.ablation_sets import Remade, datasets, ready
from stmpl.analysis.report import POOLED, write
from stmpl.files import atomic_write_text
from stmpl.metrics import pooled
from stmpl.pipeline.evaluate import evaluate_dataset, scenes_of
from stmpl.pipeline.spec import key as spec_key
from stmpl.pipeline.spec import predictor_from_spec
from stmpl.pipeline.train import read_config as read_train
from stmpl.pipeline.train import train
from stmpl.predictor import ImpossibleAnswer, OutsideEnvelope

DEFAULTS = {
    "name": None,
    "kind": "tables",  # or "stability": a sweep (stmpl/analysis/stability.py)
    "datasets": {},  # name -> {config: dataset config path, folder: where it lives}
    "in_distribution": None,  # the dataset whose test split is Table 1 (and trains set-ups)
    "out_of_distribution": [],  # datasets of Table 2 (test splits)
    "seen_thickness_mm": None,  # Table 3: the levels the subset set-ups trained on
    "setups": [],
    "out": None,  # report folder (default reports/ablation-<name>)
    "runs": None,  # training runs (default runs/ablation-<name>)
    "batch": 64,
}
SETUP_KEYS = {
    "name",
    "train",
    "predictor",
    "thickness_mm",
    "options",
    "epochs",
    "max_train",
    "limit",
    "fidelity",
    "chart",
    "truth",
    "seeds",
}
"""``limit``: evaluate on at most this many samples of each test split (the FEM takes seconds
per scene); ``fidelity``: ``full`` (the default) or ``auto`` (model no more of the part than the
scene needs, :data:`stmpl.fidelity.FIDELITIES`); ``chart: false`` keeps a set-up that differs
only in its training data (not in its speed) off the speed-vs-accuracy chart (it stays in the
tables and in the chart's table); ``truth: true`` marks the FEM at the mesh the data was made
at: the truth itself, timed only and drawn on the chart's floor (no error to measure);
``seeds``: a trained set-up trained once per seed (at least two), its rows the seeds' results
together (:func:`over_seeds`) with the spread of their relative MEEs."""


def read_config(source) -> dict:
    """A checked, complete ablation config; ``ValueError`` names what is wrong."""
    cfg = checked.read(source, DEFAULTS, "ablation config")
    ds = cfg["datasets"]
    if not isinstance(ds, dict) or not ds:
        raise ValueError("datasets must name at least one dataset: {name: {config, folder}}")
    for name, d in ds.items():
        if not isinstance(d, dict) or set(d) - {"config", "folder"} or "folder" not in d:
            raise ValueError(f"datasets.{name} needs folder (and config to make it), got {d!r}")
    if cfg["in_distribution"] not in ds:
        raise ValueError(
            f"in_distribution must be one of the datasets {sorted(ds)}, got "
            f"{cfg['in_distribution']!r}"
        )
    if not isinstance(cfg["out_of_distribution"], list) or any(
        o not in ds for o in cfg["out_of_distribution"]
    ):
        raise ValueError(
            f"out_of_distribution must list datasets of {sorted(ds)}, got "
            f"{cfg['out_of_distribution']!r}"
        )
    if not isinstance(cfg["setups"], list) or not cfg["setups"]:
        raise ValueError("setups must list at least one set-up")
    names = set()
    for i, s in enumerate(cfg["setups"]):
        if not isinstance(s, dict) or set(s) - SETUP_KEYS or "name" not in s:
            raise ValueError(
                f"setups[{i}] needs a name and takes keys {sorted(SETUP_KEYS)}, got {s!r}"
            )
        if ("train" in s) == ("predictor" in s):
            raise ValueError(
                f"setup {s['name']!r}: give either train (a training config) or "
                "predictor (fem:RES, zoo:NAME or a checkpoint)"
            )
        if s.get("fidelity", "full") not in ("full", "auto"):
            raise ValueError(
                f"setup {s['name']!r}: fidelity must be full or auto, got {s['fidelity']!r}"
            )
        seeds = s.get("seeds")
        if seeds is not None and (
            "train" not in s
            or not isinstance(seeds, list)
            or len(seeds) < 2
            or len(set(seeds)) != len(seeds)
            or not all(isinstance(x, int) and not isinstance(x, bool) and x >= 0 for x in seeds)
        ):
            raise ValueError(
                f"setup {s['name']!r}: seeds must list two or more different integers >= 0 "
                f"for a trained set-up (train:), got {seeds!r}"
            )
        for flag in ("chart", "truth"):
            if not isinstance(s.get(flag, flag == "chart"), bool):
                raise ValueError(
                    f"setup {s['name']!r}: {flag} must be true or false, got {s[flag]!r}"
                )
        if s["name"] in names:
            raise ValueError(f"setup name {s['name']!r} is used twice")
        names.add(s["name"])
    checked.one_of(cfg["kind"], "kind", ("tables", "stability"))
    checked.integer(cfg["batch"], "batch", 1)
    cfg["out"] = cfg["out"] or f"reports/ablation-{cfg['name']}"
    cfg["runs"] = cfg["runs"] or f"runs/ablation-{cfg['name']}"
    return cfg


def _kind(source) -> str:
    """The ``kind`` a config (path or mapping) declares (``tables`` unless it says)."""
    raw = source
    if not isinstance(source, dict):
        path = pathlib.Path(source)
        if not path.is_file():
            raise FileNotFoundError(f"ablation config file not found: {path}")
        try:
            raw = yaml.safe_load(path.read_text())
        except yaml.YAMLError:
            return "tables"  # read_config names the YAML error
    return raw.get("kind", "tables") if isinstance(raw, dict) else "tables"


def _hash(obj) -> str:
    return hashlib.sha256(json.dumps(obj, sort_keys=True, default=str).encode()).hexdigest()[:12]


def _slug(name: str) -> str:
    return "".join(c if c.isalnum() else "_" for c in name).strip("_").lower()


def _training_config(setup: dict, cfg: dict, ds, seed: int | None = None) -> dict:
    """The training config of set-up ``setup`` on dataset ``ds`` (with ``seed``, that seed's),
    its run folder named by the hash of everything that decides it.
    """
    t = read_train(setup["train"])
    t = copy.deepcopy(t)
    t["data"] = str(ds.folder)
    for k in ("thickness_mm", "epochs", "max_train"):
        if k in setup:
            t[k] = setup[k]
    if seed is not None:
        t["seed"] = seed
    if "options" in setup:
        t["options"] = {**t["options"], **setup["options"]}
    key = _hash([{k: v for k, v in t.items() if k not in ("out", "name")}, ds.card["hash"]])
    t["name"] = _slug(setup["name"])
    t["out"] = str(pathlib.Path(cfg["runs"]) / f"{t['name']}-{key}")
    return read_train(t)


CHART_EVERY = 60.0
"""Seconds between redrawing the report's chart while a run goes on (drawing it takes some;
the last set-up's report always has it)."""

REMADE_TOLERANCE = {"rel_mee": 0.005, "peak_err": 0.05}
"""How far (percentage points) a cached set-up may measure differently on a dataset made again
for its results to stand: under half the last digit the tables print (rel. MEE to 0.01, peak
error to 0.1), so that every cached row would read the same."""


def _job_key(setup_key: str, ds, thick, cfg: dict, s: dict) -> str:
    return _hash([setup_key, ds.card["hash"], thick, cfg["batch"], s.get("limit")])


def _setup_key(spec: str, fidelity: str) -> str:
    return spec_key(spec) + ("" if fidelity == "full" else f"@{fidelity}")


def _check_remade(name: str, ds: Remade, cfg: dict, cache: dict, progress: bool) -> dict:
    """Measure the first set-up taken as it is (``predictor:``) that the cache measured on the
    recorded dataset again on the remade one; its results stand for the recorded set's only if
    they agree within :data:`REMADE_TOLERANCE`. The verdict is kept in the cache (under the
    dataset's entry, ``remade``) and returned; a failed check raises.
    """
    rec = cache["datasets"][name]
    new = ds.card["remade_hash"]
    if rec.get("remade", {}).get("hash") == new:
        return rec["remade"]
    for s in cfg["setups"]:
        if "predictor" not in s or s.get("limit"):
            continue
        fidelity = s.get("fidelity", "full")
        key = _job_key(_setup_key(s["predictor"], fidelity), ds, None, cfg, s)
        if key in cache:
            break
    else:
        raise ValueError(
            f"dataset {name} was made again (hash {new}, recorded "
            f"{ds.card['hash']}) and no set-up taken as it is (predictor:) has a "
            "cached result on the recorded one to check it against; delete the "
            "cache entry 'datasets' to start over"
        )

    if progress:
        print(
            f"dataset {name} was made again (hash {new}, recorded {ds.card['hash']}): "
            f"measuring {s['name']} on it against its cached result"
        )
    res = evaluate_dataset(_open(s["predictor"], fidelity), ds._ds, "test", batch=cfg["batch"])
    old = cache[key]
    verdict = {
        "hash": new,
        "checked_with": s["name"],
        "samples": [int(old["samples"]), int(res["samples"])],
        **{k: [float(old[k][0]), float(res[k][0])] for k in REMADE_TOLERANCE},
    }
    off = [
        k
        for k, tol in REMADE_TOLERANCE.items()
        if not abs(verdict[k][1] - verdict[k][0]) <= tol
        and not (np.isnan(verdict[k][0]) and np.isnan(verdict[k][1]))
    ]
    if verdict["samples"][0] != verdict["samples"][1] or off:
        raise ValueError(
            f"dataset {name} made again measures differently: {s['name']} on it "
            f"{res['samples']} samples, rel. MEE {verdict['rel_mee'][1]:.4f} %, peak "
            f"{verdict['peak_err'][1]:+.2f} %; on the recorded set {old['samples']}, "
            f"{verdict['rel_mee'][0]:.4f} %, {verdict['peak_err'][0]:+.2f} %: the cached "
            "results cannot stand for it; delete the cache entry 'datasets' to start over"
        )
    rec["remade"] = verdict
    return verdict


def run(config, progress: bool = True, accept_remade: bool = False) -> dict:
    """Run (or complete) an ablation; writes the tables and ``ablation.md`` into the config's
    ``out`` and returns ``{"tables": {...}, "out": folder}``. A config of ``kind: stability``
    runs the stability sweep instead (:func:`stmpl.analysis.stability.run`). ``accept_remade``: a
    dataset made again from its recorded config whose content hash changed is checked against
    the cache (:func:`_check_remade`) and, if it measures the same, its cached results and
    training runs keep; without it such a dataset is refused.
    """
    if _kind(config) == "stability":
        return stability.run(config, progress)
    cfg = read_config(config)
    out = pathlib.Path(cfg["out"])
    out.mkdir(parents=True, exist_ok=True)
    cache_path = out / "cache.json"
    cache = json.loads(cache_path.read_text()) if cache_path.is_file() else {}
    recorded = cache.setdefault("datasets", {})
    sets = datasets(cfg, progress, recorded, accept_remade)
    remade = {
        n: _check_remade(n, ds, cfg, cache, progress)
        for n, ds in sets.items()
        if isinstance(ds, Remade)
    }
    atomic_write_text(cache_path, json.dumps(cache, indent=1, sort_keys=True))
    ind = sets[cfg["in_distribution"]]
    jobs = _jobs(cfg, sets)
    bar = None
    if progress:
        bar = tqdm(
            total=2 * len(cfg["setups"]) + len(jobs),
            unit="job",
            desc=f"ablate {cfg['name']}",
            dynamic_ncols=True,
        )
    tables: dict = {"table1": {}, "table2": {}, "table3": {}}
    points = []
    cost = {"train": 0.0, "evaluate": 0.0, "wall": 0.0}  # seconds; what the report cost
    t_run = drawn = time.perf_counter()

    def save():
        atomic_write_text(cache_path, json.dumps(cache, indent=1, sort_keys=True))

    for s in cfg["setups"]:  # one set-up at a time: trained, measured, its report out
        if bar is not None:
            bar.set_postfix_str(s["name"])
        fidelity = s.get("fidelity", "full")
        models = [
            (_open(spec, fidelity), _setup_key(spec, fidelity))
            for spec in _trained(s, cfg, ind, progress)
        ]
        if "train" in s:
            for p, _ in models:
                meta = getattr(p, "meta", {})
                cost["train"] += float(meta.get("training", {}).get("seconds", 0))
        p, setup_key = models[0]  # the one timed
        if bar is not None:
            bar.update(1)
        for _, d, thick, tab, row in [j for j in jobs if j[0] is s]:
            results = [
                _evaluated(model, model_key, sets[d], thick, cfg, s, cache, save)
                for model, model_key in models
            ]
            cost["evaluate"] += sum(r.get("evaluated_seconds", 0.0) for r in results)
            tables[tab][row] = results[0] if len(results) == 1 else over_seeds(results)
            if bar is not None:
                bar.update(1)
        ood = [tables["table2"].get(f"{s['name']} / {o}") for o in cfg["out_of_distribution"]]
        if len(ood) > 1 and all(ood):  # the paper's pooled out-of-distribution row
            tables["table2"][f"{s['name']} / {POOLED}"] = pooled_rows(ood)
        key = _hash(["latency with quartiles", setup_key, ind.card["hash"]])
        if key not in cache:
            cache[key] = _latency(p, ready(ind))
            save()
        points += _points(s, cfg, tables, cache[key])
        if bar is not None:
            bar.update(1)
        cost["wall"] = time.perf_counter() - t_run
        # the report so far; its chart (seconds to draw) at the end, or once a minute
        chart = s is cfg["setups"][-1] or time.perf_counter() - drawn > CHART_EVERY
        write(cfg, tables, out, points, remade, cost, chart)
        drawn = time.perf_counter() if chart else drawn
    if bar is not None:
        bar.close()
    return {"tables": tables, "out": out, "points": points}


def _jobs(cfg: dict, sets: dict) -> list[tuple]:
    """What to measure: ``(setup, dataset name, thickness filter, table, row label)`` for every
    set-up on the in-distribution set (Table 1), on each out-of-distribution set (Table 2) and,
    for a set-up trained on some thicknesses only, on the seen and unseen ones (Table 3).
    """
    ind, seen = cfg["in_distribution"], cfg["seen_thickness_mm"]
    jobs = []
    for s in cfg["setups"]:
        if s.get("truth"):  # the truth: nothing to measure it against
            continue
        jobs.append((s, ind, None, "table1", s["name"]))
        for o in cfg["out_of_distribution"]:
            jobs.append((s, o, None, "table2", f"{s['name']} / {o}"))
        if not (seen and "thickness_mm" in s):
            continue
        for d in [ind, *cfg["out_of_distribution"]]:
            levels = sorted({float(x) for x in sets[d].card["config"]["thickness_mm"]})
            unseen = [x for x in levels if not any(abs(x - y) < 1e-9 for y in seen)]
            where = "in-distribution" if d == ind else d
            jobs.append((s, d, list(seen), "table3", f"{s['name']} / {where}, seen thickness"))
            if unseen:
                jobs.append((s, d, unseen, "table3", f"{s['name']} / {where}, unseen thickness"))
    return jobs


def _trained(s: dict, cfg: dict, ind, progress: bool = False) -> list[str]:
    """The predictor specs of set-up ``s``: its own, or the checkpoint its training recipe
    writes, one per seed of ``seeds`` (trained on the in-distribution set ``ind`` unless it is
    there already; with ``progress``, the training's own bar of epochs shows under the
    ablation's).
    """
    if "train" not in s:
        return [s["predictor"]]
    out = []
    for seed in s.get("seeds") or [None]:
        t = _training_config(s, cfg, ind, seed)
        ckpt = pathlib.Path(t["out"]) / f"{t['name']}.safetensors"
        if not ckpt.is_file():
            ready(ind)
            ckpt = train(t, progress=progress)
        out.append(str(ckpt))
    return out


def _points(s: dict, cfg: dict, tables: dict, latency: dict) -> list[dict]:
    """The chart's points of set-up ``s``: its seconds per scene at each batch size (the
    median, and ``spread``: its quartiles over the repeats) against its error in distribution
    (``in``) and pooled over the out-of-distribution rows (``out``), each with the 95 %
    interval of its mean over the test scenes; ``truth`` for the FEM the data was made with.
    """
    truth = bool(s.get("truth", False))
    ind = None if truth else _pooled([tables["table1"].get(s["name"])])
    out = None
    if not truth and cfg["out_of_distribution"]:
        out = _pooled(
            [tables["table2"].get(f"{s['name']} / {o}") for o in cfg["out_of_distribution"]]
        )
    chart = bool(s.get("chart", True))
    points = []
    for b, (median, low, high) in latency.items():
        points.append(
            {
                "label": s["name"],
                "batch": int(b),
                "seconds": float(median),
                "spread": (low, high),
                "chart": chart,
                "truth": truth,
                "in": ind,
                "out": out,
            }
        )
    return points


def _latency(p, ds, repeats: int = 5) -> dict:
    """Seconds per scene at batch 1 and batch 64, each ``[median, lower quartile, upper
    quartile]`` over the repeats after a warm-up, on the first in-distribution test scenes;
    the FEM (seconds a scene, solved one at a time) at batch 1 only, on 3 scenes.
    """
    scenes, _ = scenes_of(ds, "test", limit=64)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", OutsideEnvelope)
        warnings.simplefilter("ignore", ImpossibleAnswer)
        p.predict(scenes[0])  # warm-up
        if not getattr(p, "batched", True):  # the FEM: seconds a scene
            return {"1": _quartiles([_timed(p, [s]) for s in scenes[:3]])}
        one = _quartiles([_timed(p, [s]) for s in scenes[: repeats * 4]])
        many = _quartiles([_timed(p, scenes) / len(scenes) for _ in range(repeats)])
    return {"1": one, str(len(scenes)): many}


def _evaluated(model, model_key: str, ds, thick, cfg: dict, s: dict, cache: dict, save) -> dict:
    """``model``'s evaluation on ``ds``'s test split (thicknesses ``thick``), from the cache
    or measured and cached (``save`` writes the cache).
    """
    key = _job_key(model_key, ds, thick, cfg, s)
    if key not in cache or "inside_broken" not in cache[key]:  # older entries: no honesty
        t0 = time.perf_counter()
        res = evaluate_dataset(
            model, ready(ds), "test", thickness_mm=thick, batch=cfg["batch"], limit=s.get("limit")
        )
        cache[key] = {**res, "evaluated_seconds": time.perf_counter() - t0}
        save()
    return cache[key]


def over_seeds(rows: list[dict]) -> dict:
    """One row of a set-up trained with several seeds, from each seed's evaluation on the same
    test scenes: every measure over all the seeds' answers together
    (:func:`stmpl.metrics.pooled`), the honesty counts summed over the seeds' answers,
    ``samples`` the scenes (each answered once per seed) and ``seeds``: their ``count``, each
    one's relative MEE (%) and its ``rows``.
    """
    out = pooled(rows)
    out["samples"] = int(rows[0]["samples"])
    out["seeds"] = {
        "count": len(rows),
        "rel_mee": [float(r["rel_mee"][0]) for r in rows],
        "rows": rows,
    }
    return out


def pooled_rows(rows: list[dict]) -> dict:
    """Table 2's pooled row over the out-of-distribution ``rows`` of one set-up
    (:func:`stmpl.metrics.pooled`); a set-up of several seeds pooled seed by seed first.
    """
    if "seeds" not in rows[0]:
        return pooled(rows)
    n = rows[0]["seeds"]["count"]
    return over_seeds([pooled([r["seeds"]["rows"][k] for r in rows]) for k in range(n)])


def _quartiles(x: list) -> list[float]:
    return [float(v) for v in np.percentile(x, [50, 25, 75])]


def _timed(p, scenes) -> float:
    t0 = time.perf_counter()
    p.predict(scenes if len(scenes) > 1 else scenes[0])
    return time.perf_counter() - t0


def _pooled(rows: list) -> dict | None:
    """Relative MEE and peak error (%) pooled over rows (:func:`stmpl.metrics.pooled`), and
    ``ci``: the half-width (%) of the 95 % interval of the pooled relative MEE's mean over the
    scenes; ``None`` without rows.
    """
    rows = [r for r in rows if r and r.get("samples")]
    if not rows:
        return None
    p = pooled(rows)
    ci = 1.96 * p["rel_mee"][1] / np.sqrt(p["samples"])
    return {"rel_mee": p["rel_mee"][0], "peak_err": p["peak_err"][0], "ci": float(ci)}


def _open(spec: str, fidelity: str = "full"):

    return predictor_from_spec(spec, fidelity=fidelity)
