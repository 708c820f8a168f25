"""One shard's work, done in a worker process (or a Dask worker on another machine): solve its
tasks by continuation over the force levels and return the samples and the failures as plain
arrays. Workers get the body part in their payload, so they need no body model and no shared
disk.
"""

from __future__ import annotations

import json
import os
import time

import numpy as np

from fem.compliance import local_compliance
from fem.local import simulate_local
from fem.material import material
from fem.placements import Plan, make_load
from fem.simulate import simulate
from fem.solver import SolverOptions
from stmpl.data.format import DOUBLES, FLOATS, INTS, STRINGS
from stmpl.part import BodyPart


def solve_shard(payload: dict) -> dict:
    """Solve the tasks of one shard (runs in a worker). Returns per-sample arrays, failures (and
    in ``failed`` each one's inputs) and timings; plain NumPy and JSON types only.
    """
    threads = payload.get("threads")
    if threads:
        for var in ("MKL_NUM_THREADS", "OMP_NUM_THREADS"):
            os.environ.setdefault(var, str(threads))

    t0 = time.perf_counter()
    cfg = payload["cfg"]
    part = BodyPart.from_arrays(
        payload["part_name"], payload["part_arrays"], payload["part_source"]
    )
    tissue = cfg.get("tissue", "paper")
    mat = material(**cfg["material"]) if tissue == "paper" else None
    phenotype = cfg["body"].get("phenotype")
    opts = SolverOptions(**cfg["solver"])
    forces = np.asarray(cfg["forces"], dtype=float)
    rec = {k: [] for k in FLOATS + INTS + DOUBLES + STRINGS}
    if cfg.get("linear"):
        rec["linear"] = []
    failures = []
    failed = {"thickness": [], "force": []}  # the inputs of each failure, in its order

    for task, (pi, ti), placement, split in payload["tasks"]:
        th_mm = cfg["thickness_mm"][ti]
        where = (task, pi, split, th_mm)  # what a failure records
        load = make_load(part, placement)
        thickness = np.full(part.n_vertices, th_mm * 1e-3)
        pressure = forces / load.area
        levels = forces[pressure <= cfg["max_pressure"]]
        for f in forces[pressure > cfg["max_pressure"]]:
            why = f"over max_pressure: {f / load.area:.0f} Pa > {cfg['max_pressure']:.0f} Pa"
            _failure(failures, failed, where, thickness, load.force * f, f, why)
        if len(levels) == 0:
            continue
        lift = None
        try:
            setup = (part, thickness, load.force, levels, cfg["resolution"], mat, opts)
            if cfg.get("fidelity", "full") == "auto":
                mesh, sols, local = simulate_local(*setup, tissue, phenotype)
                lift = local.patch.lift
            else:
                mesh, sols = simulate(*setup, tissue, phenotype)
        except ValueError as e:  # a shell that cannot be meshed (folds) is a failure too
            for f in levels:
                _failure(failures, failed, where, thickness, load.force * f, f, f"mesh: {e}")
            continue
        unit = None  # the linear FEM's answer to 1 N of the pattern
        for f, s in zip(levels, sols):
            if s.ok and "linear" in rec and unit is None:
                unit = linear_answer(part, th_mm * 1e-3, load.force, cfg, mat, opts)
            if not s.ok:
                _failure(failures, failed, where, thickness, load.force * f, f, s.reason)
                continue
            rec["task"].append(task)
            rec["placement"].append(pi)
            rec["thickness_level"].append(ti)
            rec["thickness"].append(thickness.astype(np.float32))
            rec["force"].append((load.force * f).astype(np.float32))
            u = s.part_displacement(mesh)
            if lift is not None:
                u = lift(u, part.n_vertices)
            rec["displacement"].append(u.astype(np.float32))
            if unit is not None:
                rec["linear"].append((unit * f).astype(np.float32))
            rec["total"].append(float(f))
            rec["split"].append(int(split))
            rec["kind"].append(placement["kind"])
            rec["params"].append(json.dumps(placement["params"]))
            rec["iterations"].append(s.iterations)
            rec["residual"].append(s.residual)
            rec["solve_time"].append(s.time)
            rec["min_det_F"].append(s.min_det_F)
            rec["max_compression"].append(s.max_compression)
    return {
        "shard": payload["shard"],
        "records": rec,
        "failures": failures,
        "failed": failed,
        "tasks": [t[0] for t in payload["tasks"]],
        "wall": time.perf_counter() - t0,
        "pid": os.getpid(),
    }


def _failure(failures: list, failed: dict, where: tuple, thickness, force, total, reason) -> None:
    """Record one planned sample that was not solved: its record (``where`` is its task,
    placement, split and thickness in mm) and its inputs, ``(N,)`` m and N.
    """
    task, pi, split, th_mm = where
    failures.append(
        {
            "task": task,
            "placement": pi,
            "split": int(split),
            "thickness_mm": th_mm,
            "total": float(total),
            "reason": reason,
        }
    )
    failed["thickness"].append(np.asarray(thickness, dtype=np.float32))
    failed["force"].append(np.asarray(force, dtype=np.float32))


def linear_answer(
    part: BodyPart, thickness: float, pattern: np.ndarray, cfg: dict, mat, opts
) -> np.ndarray:
    """``(N, 3)`` m: the linear FEM's displacement under the force ``pattern`` ``(N,)`` (N) on a
    uniform layer ``thickness`` (m), from the columns of its loaded vertices solved as the
    on-demand operator solves them (:func:`fem.compliance.local_compliance`), so that a model
    trained on it meets the same prior when it serves the body later (to the columns' tolerance:
    older sets started their patches at six thicknesses, not three, and their
    answers differ by under 1e-3 of the deepest).
    """
    loaded = np.flatnonzero(pattern > 0)
    G, _ = local_compliance(part, thickness, loaded, cfg["resolution"], mat, opts)
    return np.einsum("nkc,k->nc", G, pattern[loaded])


def payload(p: Plan, k: int, threads: int | None) -> dict:
    """What a worker needs to solve shard ``k`` of plan ``p`` (plain, picklable data)."""
    tasks = []
    for t in p.shard_tasks(k):
        pi, ti = p.tasks[t]
        pl = {k: v for k, v in p.placements[pi].items() if k in ("kind", "params", "touched")}
        tasks.append((t, (pi, ti), pl, int(p.split[pi])))
    return {
        "shard": k,
        "cfg": p.cfg,
        "part_name": p.part.name,
        "part_arrays": p.part.arrays(),
        "part_source": p.part.source,
        "tasks": tasks,
        "threads": threads,
    }
