"""One shard's work, done in a worker process (or a Dask worker on another machine): solve its
tasks by continuation over the force levels and return the samples and the failures as plain
arrays. Workers get the body part in their payload, so they need no body model and no shared
disk.
"""

from __future__ import annotations

import gc
import hashlib
import json
import os
import pathlib
import pickle
import sys
import time
from dataclasses import dataclass, field

import numpy as np
import trimesh

from fem.compliance import local_compliance
from fem.force_control import press_to_forces
from fem.local import simulate_local
from fem.material import material
from fem.objects import placed
from fem.placements import Plan, make_load
from fem.shapes import PRESSES
from fem.simulate import press_solver, simulate
from fem.solver import SolverOptions
from stmpl.contact.hand import SkinDistance
from stmpl.contact.posing import signed_distance
from stmpl.data.format import DOUBLES, FLOATS, INTS, STRINGS
from stmpl.files import atomic_path
from stmpl.part import BodyPart


@dataclass
class _Shard:
    """What every task of a shard shares: the part, the config's set-up, and what the tasks
    have answered so far (per-sample records, failures and each failure's inputs).
    """

    part: BodyPart
    cfg: dict
    forces: np.ndarray
    rec: dict
    failures: list = field(default_factory=list)
    failed: dict = field(default_factory=lambda: {"thickness": [], "force": []})
    tell: object = None
    """Called with 1 as each planned sample ends, solved or failed (a progress bar's tick)."""
    keep: pathlib.Path | None = None
    """Where the shard's progress is kept as its samples end
    (:func:`stmpl.data.format.progress_path`), or ``None``."""
    key: str = ""
    """What the kept progress must have been made for (:func:`_key`)."""
    done: list = field(default_factory=list)
    """The tasks ended (their samples in ``rec``)."""
    current: dict | None = None
    """The press task under way: ``task``, ``forces`` ended, its ``last`` answer (a warm start,
    ``None`` from rest) and the force that ``failed`` (or ``None``)."""
    resumed: dict = field(default_factory=dict)
    """Kept progress of a task under way when the shard last stopped, by task."""

    def __post_init__(self) -> None:
        self.tissue = self.cfg.get("tissue", "paper")
        self.mat = material(**self.cfg["material"]) if self.tissue == "paper" else None
        self.phenotype = self.cfg["body"].get("phenotype")
        self.opts = SolverOptions(**self.cfg["solver"])

    def fail(self, task, thickness, force: np.ndarray, total: float, reason: str) -> None:
        """One planned sample not solved: ``force`` ``(N,)`` (N) its input."""
        _failure(self.failures, self.failed, task.where, thickness, force, total, reason)
        self._ended()

    def add(self, task, thickness, force, displacement, total, params, diagnostics) -> None:
        """One sample: per-vertex ``thickness`` (m), ``force`` (N), ``displacement`` (m) and
        its ``total`` (N), ``params`` and ``diagnostics`` (iterations, residual, seconds,
        smallest volume ratio, largest compression).
        """
        r = self.rec
        r["task"].append(task.task)
        r["placement"].append(task.placement)
        r["thickness_level"].append(task.level)
        r["thickness"].append(thickness.astype(np.float32))
        r["force"].append(np.asarray(force).astype(np.float32))
        r["displacement"].append(displacement.astype(np.float32))
        r["total"].append(float(total))
        r["split"].append(int(task.split))
        r["kind"].append(task.spec["kind"])
        r["params"].append(json.dumps(params))
        for k, v in zip(
            ("iterations", "residual", "solve_time", "min_det_F", "max_compression"), diagnostics
        ):
            r[k].append(v)
        self._ended()

    def _ended(self) -> None:
        """A planned sample ended: kept (within a press task: its forces take minutes each) and
        ticked.
        """
        if self.current is not None:
            self.save()
        if self.tell is not None:
            self.tell(1)

    def save(self) -> None:
        """Keep what the shard has answered so far, and the task under way, in :attr:`keep`
        (written whole or not at all).
        """
        if self.keep is None:
            return
        kept = {
            "key": self.key,
            "rec": self.rec,
            "failures": self.failures,
            "failed": self.failed,
            "done": self.done,
            "current": self.current,
        }
        with atomic_path(self.keep) as tmp:
            tmp.write_bytes(pickle.dumps(kept, protocol=pickle.HIGHEST_PROTOCOL))

    def resume(self) -> int:
        """Take up the progress kept in :attr:`keep` if it was made for this shard (else say
        why not, on one line, and start over); returns how many planned samples it had ended.
        """
        if self.keep is None or not self.keep.is_file():
            return 0
        try:
            kept = pickle.loads(self.keep.read_bytes())
            if kept["key"] != self.key:
                raise ValueError("it was kept for another config or other tasks")
            rec, failures, failed = kept["rec"], kept["failures"], kept["failed"]
            done, current = list(kept["done"]), kept["current"]
        except Exception as e:  # a torn or foreign file: the shard is solved from the start
            why = str(e) or type(e).__name__
            print(
                f"{self.keep.name} not taken up ({why}): solving its shard from the start",
                file=sys.stderr,
            )
            return 0
        self.rec.update(rec)
        self.failures[:], self.done[:] = failures, done
        self.failed.update(failed)
        if current is not None:
            self.resumed[current["task"]] = current
        return len(rec["task"]) + len(failures)


@dataclass(frozen=True)
class _Task:
    """One placement at one thickness level."""

    task: int
    placement: int
    level: int
    split: int
    spec: dict
    thickness_mm: float

    @property
    def where(self) -> tuple:
        """What a failure records: task, placement, split and thickness (mm)."""
        return (self.task, self.placement, self.split, self.thickness_mm)


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
    part = part_of(payload)
    rec = {k: [] for k in FLOATS + INTS + DOUBLES + STRINGS}
    if cfg.get("linear"):
        rec["linear"] = []
    if any(t[2]["kind"] in PRESSES for t in payload["tasks"]):
        rec["pressure"], rec["push"], rec["gap"] = [], [], []
    tell = payload.get("tell")
    if tell is not None and not callable(tell):  # a queue from another process
        tell = tell.put
    keep = payload.get("keep")
    shard = _Shard(
        part,
        cfg,
        np.asarray(cfg["forces"], dtype=float),
        rec,
        tell=tell,
        keep=None if keep is None else pathlib.Path(keep),
        key=_key(payload),
    )
    taken_up = shard.resume()
    if taken_up and tell is not None:
        tell(taken_up)
    for task, (pi, ti), spec, split in payload["tasks"]:
        if task in shard.done:
            continue
        t = _Task(task, pi, ti, split, spec, cfg["thickness_mm"][ti])
        (_press if spec["kind"] in PRESSES else _shared)(shard, t)
        gc.collect()  # what a task's solves left in reference cycles (pypardiso's ctypes
        # pointers) goes now: on a worker's large heap Python's collector comes seldom
        shard.current = None
        shard.done.append(task)
        shard.save()
    return {
        "shard": payload["shard"],
        "records": rec,
        "failures": shard.failures,
        "failed": shard.failed,
        "tasks": [t[0] for t in payload["tasks"]],
        "wall": time.perf_counter() - t0,
        "pid": os.getpid(),
    }


def _shared(shard: _Shard, t: _Task) -> None:
    """One task of the paper's load model: the placement's pattern carrying each force level
    (those within ``max_pressure``), solved by continuation over the levels.
    """
    cfg, part = shard.cfg, shard.part
    load = make_load(part, t.spec)
    thickness = np.full(part.n_vertices, t.thickness_mm * 1e-3)
    pressure = shard.forces / load.area
    levels = shard.forces[pressure <= cfg["max_pressure"]]
    for f in shard.forces[pressure > cfg["max_pressure"]]:
        why = f"over max_pressure: {f / load.area:.0f} Pa > {cfg['max_pressure']:.0f} Pa"
        shard.fail(t, thickness, load.force * f, f, why)
    if len(levels) == 0:
        return
    lift = None
    try:
        setup = (part, thickness, load.force, levels, cfg["resolution"], shard.mat, shard.opts)
        if cfg.get("fidelity", "full") == "auto":
            mesh, sols, local = simulate_local(*setup, shard.tissue, shard.phenotype)
            lift = local.patch.lift
        else:
            mesh, sols = simulate(*setup, shard.tissue, shard.phenotype)
    except ValueError as e:  # a shell that cannot be meshed (folds) is a failure too
        for f in levels:
            shard.fail(t, thickness, load.force * f, f, f"mesh: {e}")
        return
    unit = None  # the linear FEM's answer to 1 N of the pattern
    for f, s in zip(levels, sols):
        if s.ok and "linear" in shard.rec and unit is None:
            unit = linear_answer(
                part, t.thickness_mm * 1e-3, load.force, cfg, shard.mat, shard.opts
            )
        if not s.ok:
            shard.fail(t, thickness, load.force * f, f, s.reason)
            continue
        u = s.part_displacement(mesh)
        if lift is not None:
            u = lift(u, part.n_vertices)
        if unit is not None:
            shard.rec["linear"].append((unit * f).astype(np.float32))
        diagnostics = (s.iterations, s.residual, s.time, s.min_det_F, s.max_compression)
        shard.add(t, thickness, load.force * f, u, f, t.spec["params"], diagnostics)


def _press(shard: _Shard, t: _Task) -> None:
    """One press task: the placement's object pushed by force control to each force level in
    turn (each from the last one's answer, :func:`fem.force_control.press_to_force`: the depth
    solved with the displacement, or found within the config's ``force_tolerance``, 1 % by
    default, where the search takes over) into the
    tissue of the whole part. Each answer is a sample: its ``force`` the contact
    force on each vertex (N: the contact pressure times the vertex's area, summing to the total
    normal contact force), ``pressure`` (Pa), ``push`` (Pa: the pressure's part along the press
    direction, the reaction's density), ``gap`` (m: each vertex's signed distance at rest
    to the object at its answer's pose, negative where the object reaches into the rest skin:
    the pose as the part sees it) and in ``params`` the object, its depth and its reaction. A level
    that fails is a failure with its reason (its input: the object's footprint carrying the
    force), and the levels after it are failures as skipped. A grip (``press_grip``) closes
    along its path: its force and reaction are the squeeze, its ``push`` its pressure, and its
    ``direction`` ``None``. The config's ``friction`` is Coulomb's between object and skin.
    """
    cfg, part = shard.cfg, shard.part
    load = make_load(part, t.spec)
    thickness = np.full(part.n_vertices, t.thickness_mm * 1e-3)
    kept = shard.resumed.pop(t.task, {"forces": 0, "last": None, "failed": None})
    forces = shard.forces[kept["forces"] :]
    shard.current = {"task": t.task, **kept}
    if kept["failed"] is not None:  # the rest follow a failure: skipped, as they would have been
        for f in forces:
            shard.current = {**shard.current, "forces": shard.current["forces"] + 1}
            shard.fail(t, thickness, load.force * f, f, f"skipped: {kept['failed']:g} N failed")
        return
    if len(forces) == 0:
        return
    try:
        shape, direction = placed(part, t.spec["kind"], t.spec["params"])
        near = _pressed_at(part, shape, t.spec)
        solver = press_solver(
            part,
            thickness,
            cfg["resolution"],
            shard.tissue,
            shard.phenotype,
            near,
            shard.opts,
            shard.mat,
        )
    except ValueError as e:  # a shell that cannot be meshed, an object that cannot be placed
        shard.current = None  # nothing solved: a stopped task starts over
        for f in forces:
            shard.fail(t, thickness, load.force * f, f, f"set-up: {e}")
        return

    def record(f: float, a) -> None:  # each force as it ends: kept, and the progress ticks
        now = shard.current
        now = {**now, "forces": now["forces"] + 1}
        if a.ok:
            now["last"] = a
        elif now["failed"] is None:
            now["failed"] = f
        shard.current = now
        if not a.ok:
            shard.fail(t, thickness, load.force * f, f, a.reason)
            return
        posed = shape.pushed(a.depth, direction)
        shard.rec["pressure"].append(a.pressure.astype(np.float32))
        shard.rec["push"].append(a.push.astype(np.float32))
        shard.rec["gap"].append(_gap(part, posed).astype(np.float32))
        params = {**t.spec["params"], "depth": a.depth, "reaction": a.reaction}
        if direction is None:  # a grip closes along its path
            params["direction"] = None
        else:
            params.update(direction=direction.tolist(), centre=posed.centre.tolist())
        # force control answers within its force tolerance: no Newton residual of its own
        diagnostics = (a.iterations, float("nan"), a.time, a.min_det_F, a.compression)
        shard.add(
            t, thickness, a.pressure * part.vertex_areas, a.displacement, f, params, diagnostics
        )

    press_to_forces(
        solver,
        shape,
        direction,
        forces,
        record,
        friction=cfg["friction"],
        start=kept["last"],
        rtol=cfg.get("force_tolerance", 0.01),
    )


def _pressed_at(part, shape, spec: dict) -> np.ndarray:
    """``(K, 3)`` where a press presses, round which the FEM refines its mesh: the vertex it is
    set on; a grip's hand vertices inside the skin once closed 5 mm.
    """
    if spec["kind"] != "press_grip":
        return part.vertices[[int(spec["params"]["at"])]]
    closed = shape.pushed(0.005, None).vertices
    return closed[SkinDistance(part)(closed) < 0]


def _gap(part, posed) -> np.ndarray:
    """``(N,)`` each rest skin vertex's signed distance to a posed object (m): the exact
    distance of a disk or a ball, uncut; a hand's (a mesh) as a scene's pose has it, cut at
    :data:`~stmpl.pose.GAP_REACH`.
    """
    if getattr(posed, "path", None) is None:
        return posed.distance(part.vertices)[0]
    mesh = trimesh.Trimesh(posed.vertices, posed.faces, process=False)
    return signed_distance(mesh, part.vertices)


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


def part_of(payload: dict) -> BodyPart:
    """The part of a :func:`payload` (a subdivided one knows the part it came from:
    :func:`stmpl.part.undivide`, on which a press is meshed).
    """
    return BodyPart.from_arrays(
        payload["part_name"], payload["part_arrays"], payload["part_source"]
    )


def _key(payload: dict) -> str:
    """What a shard's kept progress is made for: its config and tasks (a digest)."""
    what = json.dumps([payload["cfg"], payload["shard"], payload["tasks"]], default=str)
    return hashlib.sha256(what.encode()).hexdigest()[:16]


def payload(p: Plan, k: int, threads: int | None, tell=None, keep=None) -> dict:
    """What a worker needs to solve shard ``k`` of plan ``p`` (plain, picklable data);
    ``tell``: a callable, or a queue whose ``put`` is called, with 1 as each planned sample ends;
    ``keep``: a file (on a disk the worker shares) in which it keeps the shard's progress as its
    samples end, and from which it takes it up again after a stop (``None``: not kept).
    """
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
        "tell": tell,
        "keep": None if keep is None else str(keep),
    }
