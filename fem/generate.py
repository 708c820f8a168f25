"""Dataset generation: FEM ground truth for many loads, in parallel, resumable, written atomically.

A config (YAML, checked on load) names a body part, thickness levels, load placements and force
levels. Each *task* is one placement at one thickness, solved by continuation over the force
levels; each converged level is one *sample*. Tasks are grouped into *shards*; a worker solves a
whole shard and the main process writes it as ``shard-NNNNN.h5`` in one atomic rename, so a run
killed at any moment loses only shards in flight and a second run picks up the rest: no sample is
lost or written twice. Finally ``card.json`` sums up the dataset: config, counts per split, kind
and thickness, failures by reason, timings, code version and a content hash.

Splits (train / val / test) go by placement: every thickness and force level of a placement lands
in the same split.

Backends: ``serial``; ``processes`` (worker processes on this machine); ``dask`` (a
``LocalCluster`` by default, or a running scheduler's address to spread over machines; workers
get the body part in their task, so they need no body model and no shared disk).
"""

from __future__ import annotations

import datetime as _dt
import hashlib
import json
import os
import pathlib
import time
from dataclasses import dataclass

import numpy as np
import yaml

from stmpl.body.part import BodyPart
from stmpl.files import atomic_path, atomic_savez, atomic_write_text

FORMAT = "stmpl-dataset/1"
SPLITS = ("train", "val", "test")

DEFAULTS = {
    "name": None,
    "body": {"model": "anny"},
    "part": "left_arm",
    "thickness_mm": [5.0, 7.5, 10.0],
    "material": {"name": "neo_hookean", "E": 1000.0, "nu": 0.4},
    "resolution": "reference",
    "forces": [0.25, 0.5, 0.75, 1.0],
    "max_pressure": 2000.0,
    "placements": {},
    "splits": [0.8, 0.1, 0.1],
    "seed": 0,
    "shard_tasks": 4,
    "solver": {},
    "parallel": {"backend": "processes", "workers": 2, "scheduler": None},
}
PLACEMENT_KEYS = {
    "disk": {"centres", "radii"},
    "ellipse": {"centres", "semi_axes", "angles"},
    "seam_disk": {"at", "radii"},
    "band": {"at", "widths"},
    "letter": {"chars", "uv", "heights", "strokes", "angles"},
}
BODY_KEYS = {"anny": {"model", "phenotype"}, "smpl": {"model", "path", "uv_path", "betas"},
             "tube": {"model", "radius", "length", "n_around", "n_along", "taper"},
             "sheet": {"model", "width", "height", "nx", "ny"}}


# ------------------------------------------------------------------------------ config
def load_config(source) -> dict:
    """A checked, completed config from a YAML path or a dict. Unknown keys are errors."""
    if isinstance(source, (str, os.PathLike)):
        path = pathlib.Path(source)
        if not path.is_file():
            raise FileNotFoundError(f"config file not found: {path}")
        try:
            raw = yaml.safe_load(path.read_text()) or {}
        except yaml.YAMLError as e:
            raise ValueError(f"config {path} is not valid YAML: {e}") from e
        default_name = path.stem
    else:
        raw, default_name = dict(source), "dataset"
    if not isinstance(raw, dict):
        raise ValueError("a dataset config must be a mapping")
    unknown = set(raw) - set(DEFAULTS)
    if unknown:
        raise ValueError(f"unknown config keys {sorted(unknown)}; allowed: {sorted(DEFAULTS)}")
    cfg = json.loads(json.dumps(DEFAULTS))
    for k, v in raw.items():
        cfg[k] = {**cfg[k], **v} if k == "parallel" and isinstance(v, dict) else v
    cfg["name"] = cfg["name"] or default_name
    _check(cfg)
    return cfg


def _check(cfg: dict) -> None:
    body = cfg["body"]
    if not isinstance(body, dict) or body.get("model") not in BODY_KEYS:
        raise ValueError(f"body.model must be one of {sorted(BODY_KEYS)}, got {body!r}")
    bad = set(body) - BODY_KEYS[body["model"]]
    if bad:
        raise ValueError(f"unknown body keys {sorted(bad)} for model {body['model']!r}")
    th = np.asarray(cfg["thickness_mm"], dtype=float)
    from stmpl.tissue import THICKNESS_RANGE

    lo, hi = (1e3 * x for x in THICKNESS_RANGE)
    if th.ndim != 1 or len(th) == 0 or not np.all((th >= lo) & (th <= hi)):
        raise ValueError(f"thickness_mm must be a list of values in [{lo}, {hi}] mm, got "
                         f"{cfg['thickness_mm']}")
    f = np.asarray(cfg["forces"], dtype=float)
    if f.ndim != 1 or len(f) == 0 or not np.all(np.isfinite(f)) or f.min() <= 0 \
            or np.any(np.diff(f) <= 0):
        raise ValueError(f"forces must be a rising list of totals > 0 N, got {cfg['forces']}")
    if not (isinstance(cfg["max_pressure"], (int, float)) and cfg["max_pressure"] > 0):
        raise ValueError(f"max_pressure must be > 0 Pa, got {cfg['max_pressure']!r}")
    pl = cfg["placements"]
    if not isinstance(pl, dict) or not pl:
        raise ValueError("placements must name at least one load kind: "
                         f"{sorted(PLACEMENT_KEYS)}")
    for kind, spec in pl.items():
        if kind not in PLACEMENT_KEYS:
            raise ValueError(f"unknown placement kind {kind!r}; use {sorted(PLACEMENT_KEYS)}")
        if not isinstance(spec, dict) or set(spec) - PLACEMENT_KEYS[kind]:
            raise ValueError(f"placements.{kind} takes keys {sorted(PLACEMENT_KEYS[kind])}, "
                             f"got {spec!r}")
    s = np.asarray(cfg["splits"], dtype=float)
    if s.shape != (3,) or s.min() < 0 or abs(s.sum() - 1) > 1e-9:
        raise ValueError(f"splits must be three shares (train, val, test) summing to 1, got "
                         f"{cfg['splits']}")
    if not (isinstance(cfg["shard_tasks"], int) and cfg["shard_tasks"] >= 1):
        raise ValueError(f"shard_tasks must be an integer >= 1, got {cfg['shard_tasks']!r}")
    par = cfg["parallel"]
    if set(par) - set(DEFAULTS["parallel"]):
        raise ValueError(f"unknown parallel keys {sorted(set(par) - set(DEFAULTS['parallel']))}")
    if par["backend"] not in ("serial", "processes", "dask"):
        raise ValueError(f"parallel.backend must be serial, processes or dask, got "
                         f"{par['backend']!r}")
    from fem.material import material
    from fem.simulate import resolution
    from fem.solver import SolverOptions

    material(**cfg["material"])
    resolution(cfg["resolution"])
    SolverOptions(**cfg["solver"])


def config_hash(cfg: dict) -> str:
    """Hash of everything that decides the samples (not how they are computed in parallel)."""
    key = {k: v for k, v in cfg.items() if k not in ("parallel", "name")}
    return hashlib.sha256(json.dumps(key, sort_keys=True).encode()).hexdigest()[:16]


# ------------------------------------------------------------------------------ tasks
def build_part(cfg: dict) -> BodyPart:
    """The body part the config names (anny, an SMPL file, or an analytic tube / sheet)."""
    body = dict(cfg["body"])
    model = body.pop("model")
    if model == "tube":
        from stmpl.body.primitives import tube

        return tube(**body)
    if model == "sheet":
        from stmpl.body.primitives import sheet

        return sheet(**body)
    if model == "smpl":
        from stmpl.body import SMPLBody

        return SMPLBody(body["path"], uv_path=body.get("uv_path"),
                        betas=body.get("betas")).part(cfg["part"])
    from stmpl.body import AnnyBody

    return AnnyBody(phenotype=body.get("phenotype") or {}).part(cfg["part"])


def farthest_points(part: BodyPart, count: int) -> np.ndarray:
    """``count`` vertex indices spread evenly over the part (farthest-point sampling from the
    vertex nearest the centroid; deterministic)."""
    x = part.vertices
    first = int(np.argmin(np.linalg.norm(x - x.mean(0), axis=1)))
    out, d = [first], np.linalg.norm(x - x[first], axis=1)
    for _ in range(count - 1):
        nxt = int(np.argmax(d))
        out.append(nxt)
        d = np.minimum(d, np.linalg.norm(x - x[nxt], axis=1))
    return np.array(out[:count])


def placements(cfg: dict, part: BodyPart) -> list[dict]:
    """Every load placement of the config as ``{"kind", "params"}`` (params for the
    :mod:`stmpl.loads` primitive, total force left out), kinds in alphabetical order."""
    out = []
    for kind in sorted(cfg["placements"]):  # canonical order: a YAML round trip keeps task ids
        spec = cfg["placements"][kind]
        if kind in ("disk", "ellipse"):
            centres = [int(v) for v in farthest_points(part, int(spec.get("centres", 8)))]
        if kind == "disk":
            out += [{"kind": kind, "params": {"at": c, "radius": float(r)}}
                    for c in centres for r in spec.get("radii", [0.02])]
        elif kind == "ellipse":
            out += [{"kind": kind, "params": {"at": c, "semi_axes": [float(a), float(b)],
                                              "angle": float(t)}}
                    for c in centres for a, b in spec.get("semi_axes", [[0.03, 0.015]])
                    for t in spec.get("angles", [0.0])]
        elif kind == "seam_disk":
            out += [{"kind": kind, "params": {"at": float(a), "radius": float(r)}}
                    for a in spec.get("at", [0.5]) for r in spec.get("radii", [0.02])]
        elif kind == "band":
            out += [{"kind": kind, "params": {"at": float(a), "width": float(w)}}
                    for a in spec.get("at", [0.5]) for w in spec.get("widths", [0.03])]
        elif kind == "letter":
            out += [{"kind": kind, "params": {"char": str(c), "uv": [float(u), float(v)],
                                              "height": float(h), "stroke": float(s),
                                              "angle": float(t)}}
                    for c in spec.get("chars", ["A"]) for u, v in spec.get("uv", [[0.5, 0.5]])
                    for h in spec.get("heights", [0.08]) for s in spec.get("strokes", [0.01])
                    for t in spec.get("angles", [0.0])]
    return out


def make_load(part: BodyPart, placement: dict, total: float = 1.0):
    """The :class:`~stmpl.loads.Load` of a placement; names the placement if it is impossible."""
    from stmpl import loads

    params = dict(placement["params"])
    if "uv" in params:
        params["uv"] = tuple(params["uv"])
    try:
        return loads.PRIMITIVES[placement["kind"]](part, total=total, **params)
    except (ValueError, IndexError) as e:
        raise ValueError(f"impossible load placement {placement['kind']} "
                         f"{json.dumps(placement['params'])}: {e}") from e


def split_of(n_placements: int, shares, seed: int) -> np.ndarray:
    """``(P,)`` split index (0 train, 1 val, 2 test) per placement, shuffled with ``seed``."""
    order = np.random.default_rng(seed).permutation(n_placements)
    def count(share):  # every split with a share gets a placement once there are three
        n = int(round(share * n_placements))
        return max(n, 1) if share > 0 and n_placements >= 3 else n

    n_val, n_test = count(shares[1]), count(shares[2])
    n_train = n_placements - n_val - n_test
    out = np.empty(n_placements, dtype=np.int8)
    out[order[:n_train]] = 0
    out[order[n_train:n_train + n_val]] = 1
    out[order[n_train + n_val:]] = 2
    return out


@dataclass(frozen=True)
class Plan:
    """All tasks of a config: ``tasks[i] = (placement index, thickness index)``."""

    cfg: dict
    part: BodyPart
    placements: list
    split: np.ndarray
    tasks: list

    @property
    def n_shards(self) -> int:
        return -(-len(self.tasks) // self.cfg["shard_tasks"])

    def shard_tasks(self, k: int) -> list[int]:
        n = self.cfg["shard_tasks"]
        return list(range(k * n, min((k + 1) * n, len(self.tasks))))


def plan(cfg: dict, part: BodyPart | None = None) -> Plan:
    """Expand a config into tasks; every placement is built once here so a bad one fails now,
    before any solving."""
    part = part if part is not None else build_part(cfg)
    pls = placements(cfg, part)
    for p in pls:
        ld = make_load(part, p)
        p["vertices"], p["area"] = int(ld.count), float(ld.area)
    split = split_of(len(pls), cfg["splits"], cfg["seed"])
    tasks = [(i, j) for i in range(len(pls)) for j in range(len(cfg["thickness_mm"]))]
    return Plan(cfg, part, pls, split, tasks)


# ------------------------------------------------------------------------------ solving
def solve_shard(payload: dict) -> dict:
    """Solve the tasks of one shard (runs in a worker). Returns per-sample arrays, failures and
    timings; plain NumPy and JSON types only."""
    threads = payload.get("threads")
    if threads:
        for var in ("MKL_NUM_THREADS", "OMP_NUM_THREADS"):
            os.environ.setdefault(var, str(threads))
    from fem.material import material
    from fem.simulate import simulate
    from fem.solver import SolverOptions

    t0 = time.perf_counter()
    cfg = payload["cfg"]
    part = BodyPart.from_arrays(payload["part_name"], payload["part_arrays"],
                                payload["part_source"])
    mat = material(**cfg["material"])
    opts = SolverOptions(**cfg["solver"])
    forces = np.asarray(cfg["forces"], dtype=float)
    rec = {k: [] for k in ("task", "placement", "thickness_level", "thickness", "force",
                           "displacement", "total", "split", "kind", "params", "iterations",
                           "residual", "solve_time", "min_det_F", "max_compression")}
    failures = []
    for task, (pi, ti), placement, split in payload["tasks"]:
        th_mm = cfg["thickness_mm"][ti]
        load = make_load(part, placement)
        thickness = np.full(part.n_vertices, th_mm * 1e-3)
        pressure = forces / load.area
        levels = forces[pressure <= cfg["max_pressure"]]
        for f in forces[pressure > cfg["max_pressure"]]:
            failures.append({"task": task, "placement": pi, "thickness_mm": th_mm,
                             "total": float(f), "reason": f"over max_pressure: "
                             f"{f / load.area:.0f} Pa > {cfg['max_pressure']:.0f} Pa"})
        if len(levels) == 0:
            continue
        try:
            mesh, sols = simulate(part, thickness, load.force, levels, cfg["resolution"], mat,
                                  opts)
        except ValueError as e:  # a shell that cannot be meshed (folds) is a failure too
            for f in levels:
                failures.append({"task": task, "placement": pi, "thickness_mm": th_mm,
                                 "total": float(f), "reason": f"mesh: {e}"})
            continue
        for f, s in zip(levels, sols):
            if not s.ok:
                failures.append({"task": task, "placement": pi, "thickness_mm": th_mm,
                                 "total": float(f), "reason": s.reason})
                continue
            rec["task"].append(task)
            rec["placement"].append(pi)
            rec["thickness_level"].append(ti)
            rec["thickness"].append(thickness.astype(np.float32))
            rec["force"].append((load.force * f).astype(np.float32))
            rec["displacement"].append(s.part_displacement(mesh).astype(np.float32))
            rec["total"].append(float(f))
            rec["split"].append(int(split))
            rec["kind"].append(placement["kind"])
            rec["params"].append(json.dumps(placement["params"]))
            rec["iterations"].append(s.iterations)
            rec["residual"].append(s.residual)
            rec["solve_time"].append(s.time)
            rec["min_det_F"].append(s.min_det_F)
            rec["max_compression"].append(s.max_compression)
    return {"shard": payload["shard"], "records": rec, "failures": failures,
            "tasks": [t[0] for t in payload["tasks"]], "wall": time.perf_counter() - t0,
            "pid": os.getpid()}


def _payload(p: Plan, k: int, threads: int | None) -> dict:
    tasks = []
    for t in p.shard_tasks(k):
        pi, ti = p.tasks[t]
        pl = {"kind": p.placements[pi]["kind"], "params": p.placements[pi]["params"]}
        tasks.append((t, (pi, ti), pl, int(p.split[pi])))
    return {"shard": k, "cfg": p.cfg, "part_name": p.part.name,
            "part_arrays": p.part.arrays(), "part_source": p.part.source, "tasks": tasks,
            "threads": threads}


# ------------------------------------------------------------------------------ writing
def shard_path(out: pathlib.Path, k: int) -> pathlib.Path:
    return out / f"shard-{k:05d}.h5"


def write_shard(out: pathlib.Path, result: dict, chash: str) -> pathlib.Path:
    """Write one solved shard atomically."""
    import h5py

    rec = result["records"]
    n = len(rec["task"])
    path = shard_path(out, result["shard"])
    with atomic_path(path) as tmp:
        with h5py.File(tmp, "w") as h:
            h.attrs["format"] = FORMAT
            h.attrs["config_hash"] = chash
            h.attrs["shard"] = result["shard"]
            h.attrs["tasks"] = json.dumps(result["tasks"])
            h.attrs["failures"] = json.dumps(result["failures"])
            h.attrs["wall"] = result["wall"]
            h.attrs["n_samples"] = n
            for k in ("thickness", "force", "displacement"):
                shape = (0, 0, 3) if k == "displacement" else (0, 0)
                arr = np.stack(rec[k]) if n else np.zeros(shape, np.float32)
                h.create_dataset(k, data=arr, compression="gzip", compression_opts=4,
                                 shuffle=True)
            for k in ("task", "placement", "thickness_level", "split", "iterations"):
                h.create_dataset(k, data=np.asarray(rec[k], dtype=np.int32))
            for k in ("total", "residual", "solve_time", "min_det_F", "max_compression"):
                h.create_dataset(k, data=np.asarray(rec[k], dtype=np.float64))
            for k in ("kind", "params"):
                h.create_dataset(k, data=np.asarray(rec[k], dtype=object),
                                 dtype=h5py.string_dtype())
    return path


def read_shard_meta(path: pathlib.Path, chash: str | None = None) -> dict | None:
    """A finished shard's metadata, or ``None`` if it is unreadable or from another config."""
    import h5py

    try:
        with h5py.File(path, "r") as h:
            if h.attrs.get("format") != FORMAT:
                return None
            if chash is not None and h.attrs.get("config_hash") != chash:
                return None
            meta = {"shard": int(h.attrs["shard"]), "n_samples": int(h.attrs["n_samples"]),
                    "tasks": json.loads(h.attrs["tasks"]),
                    "failures": json.loads(h.attrs["failures"]), "wall": float(h.attrs["wall"])}
            for k in ("split", "thickness_level", "iterations"):
                meta[k] = h[k][()]
            for k in ("total", "solve_time", "max_compression"):
                meta[k] = h[k][()]
            meta["kind"] = [s.decode() if isinstance(s, bytes) else s for s in h["kind"][()]]
            if len(meta["split"]) != meta["n_samples"]:
                return None
            return meta
    except (OSError, KeyError, ValueError):
        return None


def code_version() -> dict:
    import subprocess

    import stmpl

    out = {"stmpl": stmpl.__version__}
    try:
        here = pathlib.Path(__file__).resolve().parent
        out["git"] = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=here,
                                    capture_output=True, text=True, timeout=5).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        pass
    return out


def write_card(out: pathlib.Path, p: Plan, chash: str, runs: list) -> dict:
    """Scan every shard and write ``card.json``; returns the card."""
    metas = []
    for k in range(p.n_shards):
        m = read_shard_meta(shard_path(out, k), chash)
        if m is None:
            raise RuntimeError(f"shard {k} is missing or unreadable; run generate again")
        metas.append(m)
    tasks = [t for m in metas for t in m["tasks"]]
    if sorted(tasks) != list(range(len(p.tasks))):
        raise RuntimeError("shards do not cover every task exactly once")
    split = np.concatenate([m["split"] for m in metas])
    level = np.concatenate([m["thickness_level"] for m in metas])
    kinds = [k for m in metas for k in m["kind"]]
    total = np.concatenate([m["total"] for m in metas])
    st = np.concatenate([m["solve_time"] for m in metas])
    its = np.concatenate([m["iterations"] for m in metas])
    comp = np.concatenate([m["max_compression"] for m in metas])
    failures = [f for m in metas for f in m["failures"]]
    reasons: dict = {}
    for f in failures:
        key = f["reason"].split(":")[0]
        reasons[key] = reasons.get(key, 0) + 1
    fail_grid: dict = {}
    for f in failures:
        key = f"{f['thickness_mm']:g} mm @ {f['total']:g} N"
        fail_grid[key] = fail_grid.get(key, 0) + 1
    th = p.cfg["thickness_mm"]
    card = {
        "format": FORMAT,
        "name": p.cfg["name"],
        "config": p.cfg,
        "config_hash": chash,
        "part": {"name": p.part.name, "vertices": p.part.n_vertices, "faces": p.part.n_faces,
                 "source": p.part.source},
        "placements": len(p.placements),
        "placements_per_split": {s: int((p.split == i).sum()) for i, s in enumerate(SPLITS)},
        "tasks": len(p.tasks),
        "samples": int(len(split)),
        "samples_per_split": {s: int((split == i).sum()) for i, s in enumerate(SPLITS)},
        "samples_per_kind": {k: kinds.count(k) for k in sorted(set(kinds))},
        "samples_per_thickness_mm": {f"{t:g}": int((level == i).sum()) for i, t in
                                     enumerate(th)},
        "samples_per_force_N": {f"{f:g}": int(np.isclose(total, f).sum())
                                for f in p.cfg["forces"]},
        "attempted": int(len(p.tasks) * len(p.cfg["forces"])),
        "failures": len(failures),
        "failures_by_reason": reasons,
        "failures_by_thickness_and_force": fail_grid,
        "max_compression": {"median": float(np.median(comp)) if len(comp) else None,
                            "max": float(comp.max()) if len(comp) else None},
        "timing": {"solve_seconds_total": float(st.sum()),
                   "solve_seconds_median_per_sample": float(np.median(st)) if len(st) else None,
                   "newton_iterations_median": float(np.median(its)) if len(its) else None,
                   "worker_seconds_total": float(sum(m["wall"] for m in metas)),
                   "runs": runs},
        "shards": [{"file": shard_path(out, m["shard"]).name, "samples": m["n_samples"]}
                   for m in metas],
        "code": code_version(),
        "created": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
    }
    h = hashlib.sha256()
    for m in metas:
        h.update(shard_path(out, m["shard"]).read_bytes())
    card["hash"] = h.hexdigest()[:16]
    atomic_write_text(out / "card.json", json.dumps(card, indent=1))
    return card


# ------------------------------------------------------------------------------ driver
def generate(config, out=None, *, workers: int | None = None, backend: str | None = None,
             scheduler: str | None = None, progress: bool = True, part: BodyPart | None = None,
             max_shards: int | None = None) -> dict:
    """Generate (or finish) the dataset of ``config`` (a YAML path or a dict) in folder ``out``
    (default ``data/<name>``). Returns the card. ``max_shards`` stops after that many new shards
    (for tests and trial runs; the card is then not written and ``{}`` is returned)."""
    cfg = load_config(config)
    par = dict(cfg["parallel"])
    if workers is not None:
        par["workers"] = int(workers)
    if backend is not None:
        par["backend"] = backend
    if scheduler is not None:
        par["backend"], par["scheduler"] = "dask", scheduler
    if par["workers"] < 1:
        raise ValueError(f"workers must be >= 1, got {par['workers']}")
    out = pathlib.Path(out if out is not None else pathlib.Path("data") / cfg["name"])
    chash = config_hash(cfg)
    out.mkdir(parents=True, exist_ok=True)
    saved = out / "config.yaml"
    if saved.exists():
        old = yaml.safe_load(saved.read_text())
        if config_hash(load_config(old)) != chash:
            raise ValueError(f"{out} holds a dataset from a different config; use another "
                             "output folder or delete it")
    p = plan(cfg, part)
    if not saved.exists():
        atomic_write_text(saved, yaml.safe_dump(cfg, sort_keys=False))
        atomic_savez(out / "part.npz", {**p.part.arrays(),
                                        "name": np.array(p.part.name),
                                        "source": np.array(json.dumps(p.part.source))})
    for stale in out.glob("shard-*.h5.*.tmp"):
        stale.unlink(missing_ok=True)
    todo = [k for k in range(p.n_shards) if read_shard_meta(shard_path(out, k), chash) is None]
    if max_shards is not None:
        todo = todo[:max_shards]
    threads = max(1, (os.cpu_count() or 1) // par["workers"])
    runs_path = out / "runs.json"
    runs = json.loads(runs_path.read_text()) if runs_path.exists() else []
    t0 = time.perf_counter()
    started = _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=p.n_shards, initial=p.n_shards - len(todo), unit="shard",
                   desc=f"generate {cfg['name']}", dynamic_ncols=True)
    done = 0
    try:
        for result in _run(p, todo, par, threads):
            write_shard(out, result, chash)
            done += 1
            if bar is not None:
                bar.update(1)
                bar.set_postfix(samples=len(result["records"]["task"]),
                                failed=len(result["failures"]))
    finally:
        if bar is not None:
            bar.close()
        if done:
            runs.append({"started": started, "wall_seconds": round(time.perf_counter() - t0, 2),
                "shards": done, "backend": par["backend"], "workers": par["workers"]})
            atomic_write_text(runs_path, json.dumps(runs, indent=1))
    if max_shards is not None and any(read_shard_meta(shard_path(out, k), chash) is None
                                      for k in range(p.n_shards)):
        return {}
    return write_card(out, p, chash, runs)


def _watch_parent(parent: int) -> None:
    """Worker initialiser: leave when the generating process is gone (killed), rather than
    finish orphaned shards that nobody will write."""
    import threading

    def watch():
        while True:
            time.sleep(0.5)
            if os.getppid() != parent:
                os._exit(1)

    threading.Thread(target=watch, daemon=True).start()


def _run(p: Plan, todo: list[int], par: dict, threads: int):
    """Yield solved shards as they finish, from the chosen backend."""
    if not todo:
        return
    if par["backend"] == "serial" or (par["backend"] == "processes" and par["workers"] == 1):
        for k in todo:
            yield solve_shard(_payload(p, k, None))
        return
    if par["backend"] == "processes":
        import concurrent.futures as cf
        import multiprocessing as mp

        with cf.ProcessPoolExecutor(par["workers"], mp_context=mp.get_context("spawn"),
                                    initializer=_watch_parent, initargs=(os.getpid(),)) as ex:
            futs = [ex.submit(solve_shard, _payload(p, k, threads)) for k in todo]
            try:
                for f in cf.as_completed(futs):
                    yield f.result()
            except BaseException:
                for f in futs:
                    f.cancel()
                raise
        return
    from dask.distributed import Client, LocalCluster, as_completed

    cluster = None
    if par["scheduler"]:
        client = Client(par["scheduler"])
    else:
        cluster = LocalCluster(n_workers=par["workers"], threads_per_worker=1, processes=True,
                               dashboard_address=None)
        client = Client(cluster)
    try:
        futs = [client.submit(solve_shard, _payload(p, k, threads), pure=False) for k in todo]
        for f in as_completed(futs):
            yield f.result()
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
