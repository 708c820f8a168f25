"""Accuracy of the zoo's models by force level (and by thickness): relative MEE and peak ratio.

For every zoo model (or those named), on the test split of a dataset: the relative MEE (%) and
the predicted / true largest displacement, averaged per total force. Shows where the linear FEM
drifts from the Neo-Hookean ground truth as the load grows, and what the learned corrections do
about it. Prints a markdown table and draws ``--out`` (PNG).

Run: python benchmarks/accuracy_by_force.py [--data data/reference] [--models linear_arm ...]
         [--out docs/accuracy_by_force.png]
"""

from __future__ import annotations

import argparse

import numpy as np
import torch

from stmpl.data.dataset import Dataset
from stmpl.metrics import sample_metrics
from stmpl.pipeline import zoo
from stmpl.table import markdown


def by_force(p, a: dict, key: str = "force") -> dict:
    """``{force N: (relative MEE %, peak ratio)}`` of predictor ``p`` over arrays ``a`` (with
    ``key="thickness"``, by thickness in mm instead).
    """
    t, f = (
        torch.tensor(a[k], dtype=torch.float32, device=p.device) for k in ("thickness", "force")
    )
    with torch.no_grad():
        u = (
            (
                torch.cat(
                    [p.forward(t[i : i + 256], f[i : i + 256]) for i in range(0, len(t), 256)]
                )
                * p.scale
            )
            .double()
            .cpu()
            .numpy()
        )
    true = a["displacement"]
    rel = np.array([sample_metrics(true[i], u[i])["rel_mee"] for i in range(len(u))])
    peak = np.linalg.norm(u, axis=-1).max(1) / np.linalg.norm(true, axis=-1).max(1)
    tot = np.round(a["total"], 3) if key == "force" else np.round(a["thickness"][:, 0] * 1e3, 2)
    return {
        float(x): (float(rel[tot == x].mean()), float(peak[tot == x].mean()))
        for x in np.unique(tot)
    } | {"all": (float(rel.mean()), float(peak.mean()))}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default="data/reference")
    ap.add_argument("--models", nargs="+", default=None, help="zoo names (default: all)")
    ap.add_argument("--out", default=None, help="write a plot here (PNG)")
    args = ap.parse_args()
    ds = Dataset(args.data)
    a = ds.arrays("test")
    res = {n: by_force(zoo.read(n), a) for n in (args.models or zoo.names())}
    forces = [k for k in next(iter(res.values())) if k != "all"]
    print(
        f"{args.data} test split ({len(a['total'])} samples): relative MEE % / predicted-to-true "
        "peak"
    )
    print()
    print(
        markdown(
            ["model", *(f"{x:g} N" for x in forces), "all"],
            [
                [n, *(f"{r[k][0]:.2f} / {r[k][1]:.3f}" for k in forces + ["all"])]
                for n, r in res.items()
            ],
            "l" + "r" * (len(forces) + 1),
        )
    )
    thick = {n: by_force(zoo.read(n), a, "thickness") for n in res}
    levels = [k for k in next(iter(thick.values())) if k != "all"]
    print()
    print(
        markdown(
            ["model", *(f"{x:g} mm" for x in levels)],
            [[n, *(f"{r[k][0]:.2f} / {r[k][1]:.3f}" for k in levels)] for n, r in thick.items()],
            "l" + "r" * len(levels),
        )
    )
    if args.out:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(9, 3.6))
        for n, r in res.items():
            ax1.plot(forces, [r[k][0] for k in forces], "o-", label=n)
            ax2.plot(forces, [r[k][1] for k in forces], "o-", label=n)
        ax1.set(
            xlabel="total force, N",
            ylabel="MEE / max displacement, %",
            ylim=(0, None),
            title="mean error",
        )
        ax2.axhline(1.0, color="k", lw=0.8)
        ax2.set(xlabel="total force, N", ylabel="predicted / true peak", title="peak")
        ax1.grid(alpha=0.3)
        ax2.grid(alpha=0.3)
        ax2.legend(fontsize=8)
        fig.suptitle(f"{ds.card['name']} test split, by force")
        fig.tight_layout()
        fig.savefig(args.out, dpi=120)
        print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
