"""Where one force of a grip dataset spends its time: the FEM's factorisations, its CG solves on
a kept factorisation, its tangent assemblies and the object's distance, counted and timed while
a task of a grip config is pressed to one force from rest, as the dataset's worker presses it.

    python benchmarks/grip_force.py [--config configs/data/forearm_grips.yaml] [--task 0]
                                    [--force 1.0] [--exact] [--force-tolerance 0.01]

The default is the first task of the grip set (anny's right hand closing on the layered forearm
at 0.3 of her left arm, 5 mm of skin and fat: 226k unknowns) to 1 N. It takes some ten minutes
of one core; run it alone, on one thread (``OMP_NUM_THREADS=1 MKL_NUM_THREADS=1``), as the
dataset's workers run. The timers wrap the solver's own methods for the run, each counting its
own time (a factorisation's assembly is the assembly's); the answer is the dataset's (its depth
and iterations are printed to compare runs and builds). ``--exact``: Uzawa's iteration solved
exactly, every equilibrium to the answer's residual (``fem.contact.UZAWA_RTOL``), to compare.
``--force-tolerance``: the share of the force the search meets it within (the config's
``force_tolerance``; the set's 1 % by default), to see what a wider one spares.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import time
from collections import defaultdict


@contextlib.contextmanager
def timed(spent: dict, inside: list, owner, name: str, label):
    """Count and time every call of ``owner.name`` into ``spent[label(args, kwargs, result)]``,
    its own time only: what the timed calls within it took (``inside``, a stack shared by the
    timers) goes to theirs.
    """
    inner = getattr(owner, name)

    def wrapper(*args, **kwargs):
        inside.append(0.0)
        t0 = time.perf_counter()
        result = None
        try:
            result = inner(*args, **kwargs)
            return result
        finally:
            took = time.perf_counter() - t0
            own = took - inside.pop()
            if inside:
                inside[-1] += took
            key = label(args, kwargs, result)
            spent[key][0] += 1
            spent[key][1] += own

    setattr(owner, name, wrapper)
    try:
        yield
    finally:
        setattr(owner, name, inner)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--config", default="configs/data/forearm_grips.yaml")
    ap.add_argument("--task", type=int, default=0)
    ap.add_argument("--force", type=float, default=1.0)
    ap.add_argument(
        "--exact", action="store_true", help="every equilibrium to the answer's residual"
    )
    ap.add_argument("--force-tolerance", type=float, default=None)
    args = ap.parse_args()

    from fem import contact, shapes, solver, tangent
    from fem.config import read_config
    from fem.placements import plan
    from fem.worker import payload, solve_shard
    from stmpl.machine import describe
    from stmpl.table import header, row

    if args.exact:
        contact.UZAWA_RTOL = contact.RTOL
    cfg = read_config(args.config)
    cfg["forces"] = [args.force]
    if args.force_tolerance is not None:
        cfg["force_tolerance"] = args.force_tolerance
    p = plan(cfg)
    shard = next(k for k in range(p.n_shards) if args.task in p.shard_tasks(k))
    spent = defaultdict(lambda: [0, 0.0])

    def factorisation(a, kw, result):
        definite = kw.get("definite", a[3] if len(a) > 3 else False)
        what = "factorisation" + (" without the pressure stiffness" if definite else "")
        return what + (" (failed: " + result[0] + ")" if result is not None else "")

    hooks = (
        (tangent.Tangent, "factorise", factorisation),
        (tangent.Tangent, "krylov", lambda a, kw, r: "CG solve on a kept factorisation"),
        (solver.Solver, "assemble", lambda a, kw, r: "tangent assembly"),
        (shapes.Surface, "distance", lambda a, kw, r: "the hand's distance"),
    )
    inside: list = []
    tries = []  # each depth the search tried: from where, what it carried, what it cost
    march = contact.Pressing.to

    def tried(self, depth, start):
        t = time.perf_counter()
        a = march(self, depth, start)
        since = 0.0 if start is None else start.depth
        tries.append((depth, since, a.reaction if a.ok else None, a.iterations, a.updates))
        tries[-1] += (time.perf_counter() - t,)
        return a

    t0 = time.perf_counter()
    with contextlib.ExitStack() as stack:
        for owner, name, label in hooks:
            stack.enter_context(timed(spent, inside, owner, name, label))
        contact.Pressing.to = tried
        try:
            out = solve_shard(payload(p, shard, 1))
        finally:
            contact.Pressing.to = march
    wall = time.perf_counter() - t0
    rec = out["records"]
    way = "exactly" if args.exact else "inexactly"
    print(
        f"{args.config}: task {args.task} to {args.force:g} N from rest (within "
        f"{100 * cfg['force_tolerance']:g} %), Uzawa {way}"
    )
    print(describe())
    if not rec["task"]:
        print(f"failed: {out['failures']}")
        return
    params = json.loads(rec["params"][-1])
    depth = params["depth"]
    print(
        f"answered: {1e3 * float(depth):.4f} mm closed, {params['reaction']:.4g} N, "
        f"{rec['iterations'][-1]} Newton iterations, {wall:.0f} s in all"
    )
    print(header(["what", "calls", "s (its own)"], "lrr"))
    for key, (n, s) in sorted(spent.items(), key=lambda kv: -kv[1][1]):
        print(row([key, str(n), f"{s:.1f}"]))
    rest = wall - sum(s for _, s in spent.values())
    print(row(["the rest (residuals, energies, set-up)", "", f"{rest:.1f}"]))
    print(f"\nthe search's {len(tries)} tries:")
    print(header(["depth mm", "from mm", "N", "iterations", "multiplier updates", "s"], "rrrrrr"))
    for depth, since, reaction, iterations, updates, took in tries:
        carried = "failed" if reaction is None else f"{reaction:.4f}"
        print(
            row(
                [
                    f"{1e3 * depth:.4f}",
                    f"{1e3 * since:.4f}",
                    carried,
                    str(iterations),
                    str(updates),
                    f"{took:.1f}",
                ]
            )
        )


if __name__ == "__main__":
    main()
