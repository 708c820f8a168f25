"""How much memory a dataset run holds as it solves shard after shard: the resident memory of
one process after each shard of a config, solved as ``stmpl generate --workers 1`` solves them
(and as each worker process of a larger run does), side by side with the same shards solved
without the worker's collection of the reference cycles each task's solves leave (after each
task), and without it with each solver in a reference cycle as well (its tangent holding its
assembly as a bound method: the solver, and PARDISO's factorisation with it, then wait for
Python's collector, which on a large heap comes seldom). Flat memory is the target: a run's
process must not grow with the shards it solved.

    python benchmarks/generate_memory.py [--config configs/data/reference_fine.yaml]
        [--shards 40 41 42 43]

Each mode runs in a fresh process, one BLAS thread; nothing is written to the dataset's folder.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time

ONE = """
import gc, json, sys, time
import yaml
import fem.worker
from fem.config import read_config
from fem.placements import plan
from fem.worker import payload, solve_shard

config, shards, collect = sys.argv[1], [int(k) for k in sys.argv[2].split(",")], sys.argv[3]
if collect != "yes":  # no collection after each task
    fem.worker.gc = type("NoCollection", (), {"collect": staticmethod(lambda: 0)})
if collect == "cycle":  # each solver in a reference cycle through its tangent
    import fem.solver

    class Cycle(fem.solver.Tangent):
        def __init__(self, linear, assemble, can_leave_out):
            super().__init__(linear, assemble, can_leave_out)
            self.held = assemble

    fem.solver.Tangent = Cycle
p = plan(read_config(yaml.safe_load(open(config))))
for k in shards:
    t = time.perf_counter()
    solve_shard(payload(p, k, None))
    pages = int(open("/proc/self/statm").read().split()[1])
    print(json.dumps({"shard": k, "seconds": time.perf_counter() - t,
                      "rss_gb": pages * 4096 / 1e9}), flush=True)
"""


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--config", default="configs/data/reference_fine.yaml")
    ap.add_argument("--shards", type=int, nargs="+", default=[40, 41, 42, 43])
    args = ap.parse_args()
    env = {**os.environ, "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
    shards = ",".join(map(str, args.shards))
    rows = {}
    for mode in ("yes", "no", "cycle"):
        out = subprocess.run(
            [sys.executable, "-c", ONE, args.config, shards, mode],
            capture_output=True,
            text=True,
            env=env,
            check=True,
        ).stdout
        rows[mode] = [json.loads(line) for line in out.splitlines() if line.startswith("{")]
    when = time.strftime("%Y-%m-%d %H:%M")
    print(f"{args.config}, shards {shards}, one process each, one thread ({when})\n")
    print(
        "| shard | as shipped: GB after it | no collection after each task | neither, and each "
        "solver in a reference cycle |"
    )
    print("|--:|--:|--:|--:|")
    for a, b, c in zip(rows["yes"], rows["no"], rows["cycle"]):
        print(f"| {a['shard']} | {a['rss_gb']:.2f} | {b['rss_gb']:.2f} | {c['rss_gb']:.2f} |")


if __name__ == "__main__":
    main()
