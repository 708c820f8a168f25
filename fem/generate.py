"""Dataset generation: FEM ground truth for many loads, in parallel, resumable, written atomically.

A config (:mod:`fem.config`) names a body part, thickness levels, load placements and force
levels. Each *task* is one placement at one thickness (:mod:`fem.placements`), solved by
continuation over the force levels; each converged level is one *sample*. Tasks are grouped into
*shards*; a worker solves a whole shard (:mod:`fem.worker`, on a :mod:`fem.backends` backend)
and the main process writes it as ``shard-NNNNN.h5`` in one atomic rename, so a run killed at any
moment loses only shards in flight and a second run picks up the rest: no sample is lost or
written twice. Finally ``card.json`` sums up the dataset: config, counts per split, kind and
thickness, failures by reason, timings, code version and the content hash (the format:
:mod:`stmpl.data.dataset`).
"""

from __future__ import annotations

import datetime as _dt
import hashlib
import json
import os
import pathlib
import subprocess
import time
from collections import Counter

import numpy as np
import yaml
from tqdm import tqdm

import stmpl
from fem.backends import run
from fem.bodies import member_folder, members
from fem.config import config_hash, defaulted, read_config
from fem.layers import preset
from fem.placements import Plan, plan
from fem.shapes import PRESSES
from stmpl.data.dataset import BODIES_FORMAT
from stmpl.data.format import (
    FORMAT,
    SPLITS,
    content_hash,
    part_hash,
    progress_path,
    read_shard_meta,
    shard_path,
    write_shard,
)
from stmpl.files import atomic_savez, atomic_write_text, folder_lock
from stmpl.part import BodyPart


def code_version() -> dict:
    """The build that runs: ``{"stmpl": version, "git": short commit}`` (no ``git`` outside a
    repository).
    """
    out = {"stmpl": stmpl.__version__}
    try:
        here = pathlib.Path(__file__).resolve().parent
        out["git"] = subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"],
            cwd=here,
            capture_output=True,
            text=True,
            timeout=5,
        ).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        pass
    return out


def _count(items, key) -> dict:
    out: dict = {}
    for x in items:
        out[key(x)] = out.get(key(x), 0) + 1
    return out


def write_card(out: pathlib.Path, p: Plan, chash: str, runs: list) -> dict:
    """Scan the shards on disk and write ``card.json``; returns the card. A set stopped part way
    gets a card of the shards it has, ``complete: false``, with how many of the planned shards,
    tasks and samples they are: it can be trained on and measured as it grows, and says so.
    """
    metas = [m for k in range(p.n_shards) if (m := read_shard_meta(shard_path(out, k), chash))]
    if not metas:
        raise ValueError(f"{out} holds no finished shard yet: there is nothing to write a card of")
    tasks = [t for m in metas for t in m["tasks"]]
    if len(set(tasks)) != len(tasks) or not set(tasks) <= set(range(len(p.tasks))):
        raise RuntimeError("the shards do not hold distinct planned tasks; generate the set again")
    split = np.concatenate([m["split"] for m in metas])
    level = np.concatenate([m["thickness_level"] for m in metas])
    kinds = [k for m in metas for k in m["kind"]]
    total = np.concatenate([m["total"] for m in metas])
    st = np.concatenate([m["solve_time"] for m in metas])
    its = np.concatenate([m["iterations"] for m in metas])
    comp = np.concatenate([m["max_compression"] for m in metas])
    failures = [f for m in metas for f in m["failures"]]
    th = p.cfg["thickness_mm"]
    written = read_part(out)

    def median(x):
        return float(np.median(x)) if len(x) else None

    card = {
        "format": FORMAT,
        "name": p.cfg["name"],
        "config": p.cfg,
        "config_hash": chash,
        "part": {
            "name": p.part.name,
            "vertices": p.part.n_vertices,
            "faces": p.part.n_faces,
            "source": p.part.source,
        },
        "placements": len(p.placements),
        "placements_skipped": {
            "count": len(p.skipped),
            "by_reason": _count(p.skipped, lambda x: x["reason"]),
        },
        "placements_per_split": {s: int((p.split == i).sum()) for i, s in enumerate(SPLITS)},
        "complete": len(metas) == p.n_shards,
        "shards_written": f"{len(metas)} of {p.n_shards}",
        "tasks": len(tasks),
        "tasks_planned": len(p.tasks),
        "samples": int(len(split)),
        "samples_per_split": {s: int((split == i).sum()) for i, s in enumerate(SPLITS)},
        "samples_per_kind": {k: kinds.count(k) for k in sorted(set(kinds))},
        "samples_per_thickness_mm": {f"{t:g}": int((level == i).sum()) for i, t in enumerate(th)},
        "tissue": getattr(preset(p.cfg["tissue"]), "name", "paper"),
        "force_range_N": [float(min(p.cfg["forces"])), float(max(p.cfg["forces"]))],
        "samples_per_force_N": {f"{f:g}": int(np.isclose(total, f).sum()) for f in p.cfg["forces"]},
        "attempted": int(len(tasks) * len(p.cfg["forces"])),
        "planned": int(len(p.tasks) * len(p.cfg["forces"])),
        "failures": len(failures),
        "failures_by_reason": _count(failures, lambda f: f["reason"].split(":")[0]),
        "failures_per_split": {
            s: sum(int(p.split[f["placement"]]) == i for f in failures)
            for i, s in enumerate(SPLITS)
        },
        "failures_by_thickness_and_force": _count(
            failures, lambda f: f"{f['thickness_mm']:g} mm @ {f['total']:g} N"
        ),
        "max_compression": {
            "median": median(comp),
            "max": float(comp.max()) if len(comp) else None,
        },
        "timing": {
            "solve_seconds_total": float(st.sum()),
            "solve_seconds_median_per_sample": median(st),
            "newton_iterations_median": median(its),
            "worker_seconds_total": float(sum(m["wall"] for m in metas)),
            "runs": runs,
        },
        "shards": [
            {
                "file": shard_path(out, m["shard"]).name,
                "samples": m["n_samples"],
                "content": m["content"],
            }
            for m in metas
        ],
        "code": code_version(),
        "created": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        "hash": content_hash(part_hash(written), [m["content"] for m in metas]),
    }
    atomic_write_text(out / "card.json", json.dumps(card, indent=1))
    return card


def read_part(out: pathlib.Path) -> BodyPart:
    """The part a dataset folder's ``part.npz`` holds (as :class:`stmpl.data.dataset.Dataset` reads
    it, so the hashes agree).
    """
    with np.load(out / "part.npz") as z:
        arrays = {k: z[k] for k in z.files}
    return BodyPart.from_arrays(str(arrays["name"]), arrays, json.loads(str(arrays["source"])))


def _check_solvable(p: Plan) -> None:
    """Refuse a config with nothing to solve: every force level of every placement over
    ``max_pressure`` (which presses, carried by the contact they make, do not meet).
    """
    shared = [pl["area"] for pl in p.placements if pl["kind"] not in PRESSES]
    if not shared:  # a press carries what its contact carries: max_pressure does not apply
        return
    smallest = min(p.cfg["forces"]) / max(shared)
    if smallest > p.cfg["max_pressure"]:
        raise ValueError(
            f"nothing to solve: even the smallest force ({min(p.cfg['forces']):g} N)"
            f" on the largest placement gives {smallest:.0f} Pa, above max_pressure "
            f"{p.cfg['max_pressure']:g} Pa"
        )


def generate(
    config,
    out=None,
    *,
    workers: int | None = None,
    backend: str | None = None,
    scheduler: str | None = None,
    progress: bool = True,
    part: BodyPart | None = None,
    max_shards: int | None = None,
    max_bodies: int | None = None,
    tissue: str | None = None,
) -> dict:
    """Generate (or finish) the dataset of ``config`` (a YAML path or a dict) in folder ``out``
    (default ``data/<name>``; ``data/<name>-<tissue>`` when ``tissue`` names a layered preset
    in place of the config's). Returns the card. ``max_shards`` stops after that many new shards
    (0: solves none), and the card then says the set is not complete (``complete: false``: a
    long set is trained on as it grows); ``max_bodies``, for a config of several bodies, stops
    after that many bodies (``{}`` is then returned: a bodies card covers every body).
    """
    cfg = read_config(config)
    if progress:
        for note in defaulted(config):
            print(f"note: the config does not set it, so {note} (the default)")
    if tissue is not None:
        cfg = read_config({**cfg, "tissue": tissue})
        if tissue != "paper" and out is None:
            out = pathlib.Path("data") / f"{cfg['name']}-{preset(cfg['tissue']).name}"
    if cfg["bodies"] is not None:  # one member dataset per body
        if part is not None:
            raise ValueError("a bodies config makes its own parts; part= is not taken")
        return generate_bodies(
            cfg,
            out if out is not None else pathlib.Path("data") / cfg["name"],
            workers=workers,
            backend=backend,
            scheduler=scheduler,
            progress=progress,
            max_shards=max_shards,
            max_bodies=max_bodies,
        )
    par = _parallel(cfg, workers, backend, scheduler)
    if max_shards is not None and (isinstance(max_shards, bool) or max_shards < 0):
        raise ValueError(f"max_shards must be an integer >= 0, got {max_shards}")
    out = pathlib.Path(out if out is not None else pathlib.Path("data") / cfg["name"])
    chash = config_hash(cfg)
    p = plan(cfg, part)
    _check_solvable(p)
    out.mkdir(parents=True, exist_ok=True)
    with folder_lock(out, f"stmpl generate {cfg['name']}"):  # one run writes a folder
        return _generate_in(out, cfg, p, chash, par, progress, max_shards)


def _generate_in(out, cfg, p: Plan, chash: str, par: dict, progress, max_shards) -> dict:
    """:func:`generate`'s work in its folder ``out``, held: the shards left solved, the card."""
    _prepare(out, cfg, p, chash)
    todo = [k for k in range(p.n_shards) if read_shard_meta(shard_path(out, k), chash) is None]
    if progress:
        for k in todo:
            if shard_path(out, k).is_file():
                print(
                    f"{shard_path(out, k).name} is unreadable, changed since it was written or "
                    "of another config: solving it again"
                )
    on_disk = len(p.tasks) - sum(len(p.shard_tasks(k)) for k in todo)  # tasks already solved
    todo = schedule(p, todo, {k for k in todo if progress_path(out, k).is_file()})
    if max_shards is not None:
        todo = todo[:max_shards]
    runs_path = out / "runs.json"
    runs = json.loads(runs_path.read_text()) if runs_path.exists() else []
    try:
        _solve(out, cfg, p, chash, todo, par, runs, progress, on_disk)
    except KeyboardInterrupt:  # the card of what is on disk, then stop as asked
        if on_disk or any(read_shard_meta(shard_path(out, k), chash) for k in todo):
            write_card(out, p, chash, runs)
        raise
    return write_card(out, p, chash, runs)


def schedule(p: Plan, todo: list[int], begun: set[int]) -> list[int]:
    """The shards of ``todo`` in the order they are solved: those ``begun`` first (a stopped
    run's kept progress resumes), then the training, validation and test shards interleaved at
    their shares among the shards left, each split's in its own order. A long set stopped part
    way therefore holds every split in proportion, and can be trained on and validated as it
    grows.
    """
    split = {k: int(p.split[p.tasks[p.shard_tasks(k)[0]][0]]) for k in todo}
    rest = [k for k in sorted(todo) if k not in begun]
    size = Counter(split[k] for k in rest)
    rank: Counter = Counter()
    key = {k: (0.0, k) for k in begun & set(todo)}
    for k in rest:  # the n-th of a split of m shards at (n + 1/2) / m of the way
        key[k] = (1 + (rank[split[k]] + 0.5) / size[split[k]], k)
        rank[split[k]] += 1
    return sorted(todo, key=key.__getitem__)


def _parallel(cfg: dict, workers, backend, scheduler) -> dict:
    """The config's ``parallel`` settings with the caller's overrides, checked."""
    par = dict(cfg["parallel"])
    if workers is not None:
        par["workers"] = workers
    if backend is not None:
        par["backend"] = backend
    if scheduler is not None:
        par["backend"], par["scheduler"] = "dask", scheduler
    w = par["workers"]
    if isinstance(w, bool) or not isinstance(w, int) or w < 1:
        raise ValueError(f"workers must be an integer >= 1, got {w!r}")
    return par


def _prepare(out: pathlib.Path, cfg: dict, p: Plan, chash: str) -> None:
    """The dataset folder: refused if it holds another config's dataset, else its part and
    config written once, and temporary files of shards a killed run left removed.
    """
    out.mkdir(parents=True, exist_ok=True)
    saved = out / "config.yaml"
    if saved.exists():
        old = yaml.safe_load(saved.read_text())
        if config_hash(read_config(old)) != chash:
            raise ValueError(
                f"{out} holds a dataset from a different config; use another "
                "output folder or delete it"
            )
    else:
        atomic_savez(
            out / "part.npz",
            {
                **p.part.arrays(),
                "name": np.array(p.part.name),
                "source": np.array(json.dumps(p.part.source)),
            },
        )
        atomic_write_text(saved, yaml.safe_dump(cfg, sort_keys=False))
    for stale in [*out.glob("shard-*.h5.*.tmp"), *out.glob("shard-*.progress.*.tmp")]:
        stale.unlink(missing_ok=True)


def _solve(
    out, cfg, p: Plan, chash: str, todo: list, par: dict, runs: list, progress, on_disk: int
) -> None:
    """Solve the shards ``todo`` on the backend ``par`` names, writing each as it arrives, with
    a progress bar of the running totals (from the ``on_disk`` tasks already solved to those and
    this run's); the run is added to ``runs.json`` even if it stops, with the shards it wrote and
    the build that solved them.
    """
    if not todo:  # nothing left to solve (or ``--max-shards 0``): no bar to draw
        return
    threads = max(1, (os.cpu_count() or 1) // par["workers"])
    t0 = time.perf_counter()
    started = _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")
    code = code_version()  # the build that solves this run's shards, whatever the checkout becomes
    bar = None
    totals = {"samples": 0, "failed": 0}
    why: Counter = Counter()  # the failures' reasons, as the progress bar sums them up
    per_task = len(cfg["forces"])
    if progress:  # planned samples: a long shard (a press's forces) moves the bar as it goes
        left = sum(len(p.shard_tasks(k)) for k in todo) * per_task
        bar = tqdm(
            total=on_disk * per_task + left,
            initial=on_disk * per_task,
            unit="sample",
            desc=f"generate {cfg['name']}",
            dynamic_ncols=True,
        )
    tell = bar.update if bar is not None and par["backend"] != "dask" else None
    done, written = 0, []
    try:
        for result in run(p, todo, par, threads, tell, lambda k: progress_path(out, k)):
            write_shard(
                out,
                result["shard"],
                result["records"],
                {
                    "config_hash": chash,
                    "tasks": result["tasks"],
                    "failures": result["failures"],
                    "wall": float(result["wall"]),
                },
                result.get("failed"),
            )
            progress_path(out, result["shard"]).unlink(missing_ok=True)
            done += 1
            written.append(int(result["shard"]))
            totals["samples"] += len(result["records"]["task"])
            totals["failed"] += len(result["failures"])
            why.update(f["reason"].split(":")[0] for f in result["failures"])
            if bar is not None:
                if tell is None:  # counted as the shard arrives
                    bar.update(len(result["tasks"]) * per_task)
                top = ", ".join(f"{n} {r}" for r, n in why.most_common(2))
                bar.set_postfix(totals | ({"why": top} if top else {}))  # this run's totals
    finally:
        if bar is not None:
            bar.close()
        if done:
            runs.append(
                {
                    "started": started,
                    "wall_seconds": round(time.perf_counter() - t0, 2),
                    "shards": done,
                    "written": sorted(written),  # which build solved which shard
                    "code": code,
                    "backend": par["backend"],
                    "workers": par["workers"],
                }
            )
            atomic_write_text(out / "runs.json", json.dumps(runs, indent=1))


def generate_bodies(cfg: dict, out, max_bodies: int | None = None, **kwargs) -> dict:
    """Generate (or finish) every member of a ``bodies`` config in ``out`` and write
    ``bodies.json`` when all are done; ``max_bodies`` stops after the first that many (each
    an ordinary dataset already). ``kwargs`` go to :func:`generate`. Returns the
    bodies card (``{}`` if a member stopped early or ``max_bodies`` left some out).
    """
    out = pathlib.Path(out)
    out.mkdir(parents=True, exist_ok=True)
    ms = members(cfg)
    saved = out / "bodies.yaml"
    if saved.exists():
        if config_hash(read_config(yaml.safe_load(saved.read_text()))) != config_hash(cfg):
            raise ValueError(
                f"{out} holds datasets from a different config; use another "
                "output folder or delete it"
            )
    else:
        atomic_write_text(saved, yaml.safe_dump(cfg, sort_keys=False))
    cards = []
    if max_bodies is not None and max_bodies < 1:
        raise ValueError(f"max_bodies must be >= 1, got {max_bodies}")
    for k, m in enumerate(ms):
        if max_bodies is not None and k >= max_bodies:
            return {}
        if kwargs.get("progress", True):
            ph = (
                ", ".join(f"{a} {v:.2f}" for a, v in m["body"]["phenotype"].items())
                if "phenotype" in m["body"]
                else f"betas {m['body']['betas']}"
            )
            print(f"body {k + 1}/{len(ms)}: {ph}; {m['thickness_mm'][0]:g} mm", flush=True)
        card = generate(m, member_folder(out, k), **kwargs)
        if not card["complete"]:
            return {}
        cards.append(card)
    card = {
        "format": BODIES_FORMAT,
        "name": cfg["name"],
        "config": cfg,
        "config_hash": config_hash(cfg),
        "members": [
            {
                "folder": member_folder(out, k).name,
                "name": c["name"],
                "phenotype": ms[k]["body"]["phenotype"]
                if "phenotype" in ms[k]["body"]
                else {"betas": ms[k]["body"]["betas"]},
                "thickness_mm": ms[k]["thickness_mm"],
                "hash": c["hash"],
                "samples": c["samples"],
                "samples_per_split": c["samples_per_split"],
                "failures": c["failures"],
            }
            for k, c in enumerate(cards)
        ],
        "samples": sum(int(c["samples"]) for c in cards),
        "hash": hashlib.sha256(" ".join(c["hash"] for c in cards).encode()).hexdigest()[:16],
    }
    atomic_write_text(out / "bodies.json", json.dumps(card, indent=1))
    return card
