"""Where the paper's gel stops answering: the skin's compression at which the FEM's force
ramps buckle, read from datasets that keep their failed solves.

    python benchmarks/gel_failure.py --generate configs/data/gel_failure.yaml data/gel_failure
    python benchmarks/gel_failure.py data/gel_failure [data/honesty_arm ...]

Each placement at each thickness is a force ramp (the dataset's force levels, each solved from
the last). A ramp *buckles* where a level fails with an indefinite tangent or stagnates after
a solved level: the gel creased between the two. For each buckled ramp the last solved
compression (how far the skin moved inward, a share of the tissue's depth) is a lower bound of
where it creased. The table gives their distribution and, for candidate bounds, how many
solved answers lie past each, and how many of those were followed by a buckle: the bound past
which an answer on the gel is not trusted (:data:`stmpl.tissue.GEL_TRUSTED_COMPRESSION`).
``--generate`` makes a dataset with that bound lifted (the FEM then answers as far as it
converges), which is what the measurement needs; a set made under the bound stops each ramp
at it.
"""

from __future__ import annotations

import argparse
import collections
import glob
from pathlib import Path

import numpy as np

from fem.generate import generate
from fem.material import NeoHookean
from stmpl.data.format import read_failed, read_shard

BUCKLED = ("indefinite", "stagnated")
"""Failure reasons that mean the gel lost stability (not a mesh refusal or a skipped level)."""


def ramps(folder: Path) -> dict:
    """``{(placement, thickness_mm): [(force N, compression or None, reason)]}``, forces rising."""
    out = collections.defaultdict(list)
    shards = sorted(glob.glob(str(folder / "shard-*.h5")))
    if not shards:
        raise SystemExit(f"{folder}: no dataset shards (make it with `stmpl generate`)")
    for path in shards:
        a, _ = read_shard(path, ("thickness", "total", "placement", "max_compression"))
        for i in range(len(a["total"])):
            key = (int(a["placement"][i]), round(float(a["thickness"][i, 0]) * 1e3, 2))
            out[key].append((float(a["total"][i]), float(a["max_compression"][i]), ""))
        failed = read_failed(path)
        if failed is None:
            raise SystemExit(f"{path}: written before failed solves kept their records")
        for f in failed[0]:
            key = (int(f["placement"]), round(float(f["thickness_mm"]), 2))
            out[key].append((float(f["total"]), None, f["reason"]))
    return {k: sorted(v) for k, v in out.items()}


def last_before_buckling(ramp: list) -> float | None:
    """The last solved compression of a ramp whose next level buckled, else ``None``."""
    for (_, c, _), (_, c2, why) in zip(ramp, ramp[1:]):
        if c is not None and c2 is None and why.startswith(BUCKLED):
            return c
    return None


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("data", nargs="+", type=Path, help="dataset folders (paper tissue)")
    ap.add_argument(
        "--generate",
        type=Path,
        metavar="CONFIG",
        help="first generate the (one) dataset folder from this config, the gel's bound lifted",
    )
    ap.add_argument("--bounds", nargs="+", type=float, default=[0.4, 0.45, 0.5, 0.6, 0.8])
    args = ap.parse_args(argv)
    if args.generate is not None:
        if len(args.data) != 1:
            raise SystemExit("--generate makes one dataset: give one folder")
        NeoHookean.limits = None  # the measurement must see past the bound it measures
        generate(args.generate, args.data[0])
    all_ramps = {}
    for folder in args.data:
        all_ramps.update({(str(folder), *k): v for k, v in ramps(folder).items()})
    solved = [(c, r) for r in all_ramps.values() for _, c, _ in r if c is not None]
    last = np.array([x for r in all_ramps.values() if (x := last_before_buckling(r)) is not None])
    comp = np.array([c for c, _ in solved])
    print(f"datasets: {', '.join(map(str, args.data))}")
    print(f"{len(all_ramps)} force ramps, {len(comp)} solved answers, {len(last)} ramps buckled")
    q = np.percentile(last, [0, 25, 50, 75, 90, 100])
    print(
        "last solved compression before buckling: "
        + ", ".join(f"{n} {v:.2f}" for n, v in zip(("min", "25%", "50%", "75%", "90%", "max"), q))
    )
    print(
        "| bound | solved answers past it | of those, followed by a buckle | buckled ramps whose "
        "last answer lies past it |"
    )
    print("|--:|--:|--:|--:|")
    for b in args.bounds:
        past = [(c, r) for c, r in solved if c > b]
        followed = sum(
            1
            for c, r in past
            for (_, c1, _), (_, c2, why) in zip(r, r[1:])
            if c1 == c and c2 is None and why.startswith(BUCKLED)
        )
        print(f"| {b:g} | {len(past)} | {followed} | {int((last > b).sum())} of {len(last)} |")


if __name__ == "__main__":
    main()
