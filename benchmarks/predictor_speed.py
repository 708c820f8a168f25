"""How fast the shipped models answer, and how far from what this CPU can do.

    python benchmarks/predictor_speed.py [--models gnn_arm_bodies uv_unet_arm_bodies ...]
        [--repeat 30] [--threads 2] [--compiled]

Each zoo model (default: the command line's default GNN and UV-UNet, the linear FEM and
Naive) answers scenes on the skin it was made for (the once-subdivided left arm: 0.3 N disks
of 2 cm radius on 7.5 mm of tissue; at batch 1 one scene, at batch 64 sixty-four at different
places and forces), at fidelity ``full`` and ``auto``. Beside the median time per scene of the
whole ``predict()`` (features, prior, network, envelope, the answer): the network's own time
(its ``forward``, timed by hooks, the prior excluded), the share of ``predict()`` spent outside
it, the network's floating-point work per scene (``torch.utils.flop_counter``: matrix products
and convolutions) and the rate it achieves, against this CPU's fp32 matrix-product rate
(a 1024 x 1024 product, the best of a few). Each model first loads its compiled loops
(``predictor.load_kernels()``: the GNN's subgraph kernel and fused processor steps), as an
application answering many scenes does. The last column is batch 64's time per scene over
batch 1's: below 1 a batch pays. With ``--compiled`` each learned model is measured again with
its network compiled (``predictor.compile()``, :mod:`models.compiled`; the compile's seconds
are printed). A kind with a NumPy inference (the GNN; ``stmpl simulate`` answers with it) is
measured that way too, in a row of its own (its products use NumPy's BLAS threads, set by
``OMP_NUM_THREADS``, not ``--threads``). Targets: the default GNN at ``auto`` and batch 1 in at most
1 ms, the UV-UNet in at most 2 ms; at batch 64 a quarter of batch 1's time per scene. Run it
alone: the times are wall-clock.
"""

from __future__ import annotations

import argparse
import time
import warnings
from importlib.metadata import entry_points

import numpy as np
import torch
from torch.utils.flop_counter import FlopCounterMode

from stmpl import AnnyBody, Scene, loads, tissue
from stmpl.machine import describe
from stmpl.pipeline import zoo
from stmpl.predictor import NUMPY as NUMPY_GROUP
from stmpl.predictor import ImpossibleAnswer, OutsideEnvelope
from stmpl.table import header, row

DEFAULT = ["gnn_arm_bodies", "uv_unet_arm_bodies", "linear_arm_fine", "naive_arm_fine"]
NUMPY = {ep.name for ep in entry_points(group=NUMPY_GROUP)}
"""The kinds with a NumPy inference (``engine="numpy"``), measured beside their torch rows."""


def scenes(arm, n: int, seed: int = 0) -> list[Scene]:
    """``n`` disk scenes (2 cm radius, 0.1-0.5 N, 7.5 mm) on the middle of ``arm``'s chart."""
    rng = np.random.default_rng(seed)
    thick = tissue.constant(arm, 0.0075)
    out = []
    while len(out) < n:
        uv = (0.5, 0.5) if not out else tuple(rng.uniform(0.38, 0.62, 2))
        force = 0.3 if not out else float(rng.uniform(0.1, 0.5))
        try:
            out.append(
                Scene.from_load(arm, thick, loads.disk(arm, uv=uv, radius=0.02, total=force))
            )
        except ValueError:  # off the chart: another place
            continue
    return out


def gemm_rate(n: int = 1024, tries: int = 5) -> float:
    """This CPU's fp32 matrix-product rate, GFLOP/s (the best of ``tries``)."""
    a, b = torch.randn(n, n), torch.randn(n, n)
    a @ b
    best = np.inf
    for _ in range(tries):
        t0 = time.perf_counter()
        a @ b
        best = min(best, time.perf_counter() - t0)
    return 2 * n**3 / best / 1e9


class NetworkClock:
    """Wall time spent inside ``module``'s forward calls, by hooks."""

    def __init__(self, module: torch.nn.Module):
        self.seconds, self._t0 = 0.0, None
        module.register_forward_pre_hook(self._start)
        module.register_forward_hook(self._stop)

    def _start(self, *_):
        self._t0 = time.perf_counter()

    def _stop(self, *_):
        self.seconds += time.perf_counter() - self._t0


def measure(p, batch: list[Scene], repeat: int) -> dict:
    """Median seconds per scene of ``p.predict(batch)``, and the network's share of it."""
    one = len(batch) == 1
    arg = batch[0] if one else batch
    clock = NetworkClock(p.model) if hasattr(p, "model") else None
    for _ in range(2):
        p.predict(arg)  # warm-up: caches, the prior's columns
    totals, nets = [], []
    for _ in range(repeat):
        if clock is not None:
            clock.seconds = 0.0
        t0 = time.perf_counter()
        p.predict(arg)
        totals.append(time.perf_counter() - t0)
        nets.append(clock.seconds if clock is not None else 0.0)
    k = int(np.argsort(totals)[len(totals) // 2])  # the median call, and its network time
    return {"seconds": totals[k] / len(batch), "network": nets[k] / len(batch)}


def flops(p, scene: Scene) -> float:
    """Floating-point operations of the network's forward per scene (prior excluded)."""
    if not hasattr(p, "model"):
        return 0.0
    counter = FlopCounterMode(display=False)
    with torch.no_grad():
        p.predict(scene)  # warm: nothing left to cache
        with counter:
            p.predict(scene)
    total = counter.get_total_flops()
    prior = getattr(p.model, "prior", None)
    if prior is not None:  # the prior's product is not the network's
        with torch.no_grad(), FlopCounterMode(display=False) as alone:
            p.base(*_inputs(p, scene))
        total -= alone.get_total_flops()
    return float(total)


def _inputs(p, scene: Scene):
    t = torch.tensor(scene.thickness[None], dtype=torch.float32, device=p.device)
    f = torch.tensor(scene.force[None], dtype=torch.float32, device=p.device)
    return t, f, None, None


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--models", nargs="+", default=DEFAULT)
    ap.add_argument("--repeat", type=int, default=30)
    ap.add_argument("--threads", type=int, default=torch.get_num_threads())
    ap.add_argument(
        "--compiled", action="store_true", help="measure each learned model compiled too"
    )
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    warnings.simplefilter("ignore", OutsideEnvelope)
    warnings.simplefilter("ignore", ImpossibleAnswer)
    arm = AnnyBody().part("left_arm").subdivided(1)
    many = scenes(arm, 64)
    rate = gemm_rate()
    print(f"{describe()}; {args.threads} threads; fp32 matrix products {rate:.0f} GFLOP/s")
    print(f"left arm, {arm.n_vertices} vertices; median of {args.repeat} calls\n")
    cols = [
        "model",
        "fidelity",
        "ms/scene, batch 1",
        "network ms",
        "outside the network",
        "MFLOP/scene",
        "GFLOP/s",
        "ms/scene, batch 64",
        "batch 64 / batch 1",
    ]
    print(header(cols, "llrrrrrrr"))
    for name in args.models:
        for fidelity in ("full", "auto"):
            try:
                p = zoo.read(name, fidelity=fidelity)
            except (TypeError, ValueError) as e:  # a model without fidelities
                print(f"{name} at {fidelity}: {e}")
                continue
            p.load_kernels()  # many answers: as a loop or a viewer runs them
            work = flops(p, many[0])
            print(row(report(name, fidelity, p, many, args.repeat, work)))
            if p.name in NUMPY:  # the same model answered with NumPy alone (no torch)
                q = zoo.read(name, fidelity=fidelity, engine="numpy")
                print(row(report(name, f"{fidelity}, NumPy", q, many, args.repeat, work)))
            if args.compiled and p.name in ("gnn", "uv_unet"):  # a network to compile
                seconds = p.compile(many[0])
                label = f"{fidelity}, compiled ({seconds:.0f} s)"
                print(row(report(name, label, p, many, args.repeat, work)))


def report(name: str, label: str, p, many: list[Scene], repeat: int, work: float) -> list[str]:
    """One row of the table: ``p`` at batch 1 and 64 on ``many``; ``work``: its network's
    floating-point operations per scene (:func:`flops`).
    """
    if hasattr(p, "model"):
        p.model.eval()
    with torch.no_grad():
        one = measure(p, many[:1], repeat)
        lots = measure(p, many, max(3, repeat // 6))
    net = one["network"]
    timed = hasattr(p, "model")  # a torch network, timed by hooks
    return [
        name,
        label,
        f"{1e3 * one['seconds']:.2f}",
        f"{1e3 * net:.2f}" if timed else "-",
        f"{100 * (1 - net / one['seconds']):.0f} %" if timed else "-",
        f"{work / 1e6:.1f}",
        f"{work / net / 1e9:.1f}" if net > 0 else "-",
        f"{1e3 * lots['seconds']:.2f}",
        f"{lots['seconds'] / one['seconds']:.2f}",
    ]


if __name__ == "__main__":
    main()
