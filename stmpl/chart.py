"""The speed-vs-accuracy chart: time per scene (log) against the out-of-distribution error,
one point per method and batch size, the Pareto front drawn, the paper's reported point marked
as a reference (not a measurement of ours)."""

from __future__ import annotations

import pathlib

import numpy as np

FAMILIES = {  # family: colour
    "FEM": "#444444", "linear FEM": "#1f77b4", "UV-UNet": "#d62728", "GNN": "#2ca02c",
    "Naive": "#9467bd", "other": "#8c564b"}
PAPER_POINT = {"seconds": 0.002, "rel_mee": 5.57,
               "label": "paper's UV-UNet (reported: A6000 GPU, its data)"}


def family(name: str) -> str:
    """The family of a set-up from its name (for the colour)."""
    low = name.lower()
    for key, fam in (("linear", "linear FEM"), ("fem", "FEM"), ("unet", "UV-UNet"),
                     ("gnn", "GNN"), ("naive", "Naive")):
        if key in low:
            return fam
    return "other"


def pareto(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Indices of the points no other point beats on both ``x`` and ``y`` (lower is better),
    ordered by ``x``."""
    order = np.lexsort((y, x))
    front, best = [], np.inf
    for i in order:
        if y[i] < best:
            front.append(i)
            best = y[i]
    return np.asarray(front, dtype=int)


def speed_accuracy(points: list[dict], path, title: str = "") -> list[pathlib.Path]:
    """Draw ``points`` (each: ``label``, ``seconds`` per scene, ``rel_mee`` %, ``peak_err`` %
    signed, ``batch``) into ``path`` as PNG and SVG; returns the files written."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.ticker

    if not points:
        raise ValueError("no points to chart")
    fig, axes = plt.subplots(1, 2, figsize=(13, 5.4))
    x = np.array([p["seconds"] * 1e3 for p in points])
    for ax, key, what in ((axes[0], "rel_mee", "out-of-distribution relative MEE, %"),
                          (axes[1], "peak_err", "out-of-distribution |peak error|, %")):
        y = np.array([abs(p[key]) for p in points])
        ok = np.isfinite(x) & np.isfinite(y) & (x > 0)
        for fam, colour in FAMILIES.items():
            for batched, marker in ((False, "o"), (True, "s")):
                sel = [i for i, p in enumerate(points) if ok[i] and family(p["label"]) == fam
                       and (p.get("batch", 1) > 1) == batched]
                if sel:
                    ax.scatter(x[sel], y[sel], c=colour, marker=marker, s=46, zorder=3,
                               edgecolors="white", linewidths=0.6,
                               label=f"{fam}, {'batched' if batched else 'batch 1'}")
        idx = np.flatnonzero(ok)
        front = idx[pareto(x[idx], y[idx])]
        if len(front) > 1:
            ax.step(x[front], y[front], where="post", c="#999999", lw=1.2, ls="--", zorder=2,
                    label="Pareto front")
        for i in idx:
            b = points[i].get("batch", 1)
            ax.annotate(points[i]["label"] + ("" if b == 1 else f" (batch {b})"),
                        (x[i], y[i]), xytext=(4, 3), textcoords="offset points", fontsize=7,
                        color="#333333")
        if key == "rel_mee":
            ax.scatter([PAPER_POINT["seconds"] * 1e3], [PAPER_POINT["rel_mee"]], marker="*",
                       s=160, facecolors="none", edgecolors="black", zorder=4,
                       label=PAPER_POINT["label"])
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("time per scene, ms (log; this CPU unless marked)")
        ax.set_ylabel(what + " (log)")
        ax.grid(True, which="both", alpha=0.25)
        ax.yaxis.set_major_formatter(matplotlib.ticker.FormatStrFormatter("%g"))
        ax.yaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
        ax.xaxis.set_major_formatter(matplotlib.ticker.FormatStrFormatter("%g"))
    handles, labels = axes[0].get_legend_handles_labels()
    seen = dict(zip(labels, handles))
    fig.legend(seen.values(), seen.keys(), loc="lower center", ncol=4, fontsize=8,
               frameon=False)
    fig.suptitle(title or "Speed against accuracy: lower left is better", fontsize=12)
    fig.tight_layout(rect=(0, 0.12, 1, 0.95))
    path = pathlib.Path(path)
    base = path.with_suffix("")
    base.parent.mkdir(parents=True, exist_ok=True)
    out = [base.with_suffix(".png"), base.with_suffix(".svg")]
    fig.savefig(out[0], dpi=130)
    fig.savefig(out[1])
    plt.close(fig)
    return out
