"""Predictor latency and throughput on the anny left arm, side by side.

For each learned predictor (untrained weights: speed does not depend on them; the linear FEM
operator, where one is used, is the zoo's ``linear_arm``): the median time
per scene of ``predict(scene)`` at batch 1 (the whole API: tensors, UV maps, Deformation) and of
the bare forward pass, and scenes per second at batch 64. The FEM (reference resolution) is timed
once for scale.

Run: python benchmarks/predictor_speed.py [--repeat 30] [--device cpu|cuda] [--fem]
Target: <= 5 ms per scene at batch 1 on this CPU for each learned predictor.
"""

from __future__ import annotations

import argparse
import os
import platform

import torch
from _timing import median_time

from stmpl.table import header, row

CONFIGS = {
    "naive": {},
    "uv_unet-paper": {},  # 128 px, width 16, depth 5, dropout 0.5
    "uv_unet-plain": {"depth": 3, "dropout": 0.0, "per_newton": True},  # no prior
    "uv_unet-256": {"size": 256, "depth": 6},
    "gnn-mgn": {},  # MeshGraphNets: latent 128, 15 steps
    "gnn-64x8": {"latent": 64, "steps": 8},
    "gnn-32x8": {"latent": 32, "steps": 8, "per_newton": True},  # the first zoo GNN
    "gnn-plain": {"latent": 32, "steps": 6, "per_newton": True},  # no prior
    # on the linear FEM operator of the arm (the zoo's linear_arm operator, installed)
    "linear": {},
    "uv_unet-shipped": {"depth": 3, "dropout": 0.0, "per_newton": True, "prior": "linear"},
    "gnn-prior-32x6": {"latent": 32, "steps": 6, "per_newton": True, "prior": "linear"},
    "gnn-shipped": {"latent": 32, "steps": 3, "per_newton": True, "prior": "linear"},
}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=30)
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--fem", action="store_true", help="also time the FEM (reference mesh)")
    args = ap.parse_args()
    from stmpl import AnnyBody, loads, predictor, tissue
    from stmpl.scene import Scene

    torch.manual_seed(0)
    arm = AnnyBody().part("left_arm")
    scene = Scene.from_load(
        arm, tissue.constant(arm, 0.0075), loads.disk(arm, uv=(0.5, 0.5), radius=0.02, total=0.3)
    )
    batch = [scene] * 64
    dev = args.device
    from stmpl.pipeline import zoo

    operator = zoo.read("linear_arm", device=dev)  # the arm's linear FEM operator, 5 levels
    print(
        f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
        f"torch {torch.__version__}, {torch.get_num_threads()} threads, device {dev}"
        + (f" ({torch.cuda.get_device_name()})" if dev.startswith("cuda") else "")
    )
    print(f"left arm, {arm.n_vertices} vertices; median of {args.repeat} runs")
    print()
    columns = ["predictor", "parameters", "MB", "predict() ms, batch 1", "forward ms, batch 1"]
    print(header(columns + ["scenes/s, batch 64"], "lrrrrr"))
    t1 = torch.tensor(scene.thickness[None], dtype=torch.float32, device=dev)
    f1 = torch.tensor(scene.force[None], dtype=torch.float32, device=dev)
    for label, opts in CONFIGS.items():
        p = predictor.create(label.split("-")[0], arm, opts, device=dev)
        if label == "linear" or opts.get("prior") == "linear":
            op = operator.model
            (p.model if label == "linear" else p.model.prior).set(op.levels, op.index, op.values)
        p.model.eval()
        sync = torch.cuda.synchronize if dev.startswith("cuda") else (lambda: None)

        def fwd():
            with torch.no_grad():
                p.forward(t1, f1)
            sync()

        t_pred = median_time(lambda: p.predict(scene), args.repeat, 2)
        t_fwd = median_time(fwd, args.repeat, 2)
        t_b = median_time(lambda: p.predict(batch), max(3, args.repeat // 5), 2)
        n = p.n_parameters()
        cells = [label, n, f"{4 * n / 2**20:.1f}", f"{1e3 * t_pred:.2f}", f"{1e3 * t_fwd:.2f}"]
        print(row(cells + [f"{64 / t_b:.0f}"]))
    if args.fem:
        p = predictor.create("fem")
        t = median_time(lambda: p.predict(scene), 3)
        print(row(["fem (reference mesh)", "-", "-", f"{1e3 * t:.0f}", "-", f"{1 / t:.1f}"]))


if __name__ == "__main__":
    main()
