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
    names = []                                  # (axes, points to name) once laid out
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
        for label in {points[i]["label"] for i in idx}:     # a set-up's batch sizes, joined
            mine = sorted((x[i], y[i]) for i in idx if points[i]["label"] == label)
            if len(mine) > 1:
                ax.plot(*zip(*mine), c=FAMILIES[family(label)], lw=0.8, alpha=0.5, zorder=2)
        if key == "rel_mee":
            ax.scatter([PAPER_POINT["seconds"] * 1e3], [PAPER_POINT["rel_mee"]], marker="*",
                       s=160, facecolors="none", edgecolors="black", zorder=4,
                       label=PAPER_POINT["label"])
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("time per scene, ms (log; this CPU unless marked)")
        ax.set_ylabel(what + " (log)")
        ax.grid(True, which="both", alpha=0.25)
        fmt = matplotlib.ticker.FuncFormatter(lambda v, _: f"{v:g}")
        for axis in (ax.xaxis, ax.yaxis):                   # 1-2-5 ticks, labelled
            axis.set_major_locator(matplotlib.ticker.LogLocator(subs=(1.0, 2.0, 5.0)))
            axis.set_major_formatter(fmt)
            axis.set_minor_formatter(matplotlib.ticker.NullFormatter())
        names.append((ax, [(x[i], y[i], points[i]["label"]) for i in idx
                           if points[i].get("batch", 1) == 1]))
    handles, labels = axes[0].get_legend_handles_labels()
    seen = dict(zip(labels, handles))
    fig.legend(seen.values(), seen.keys(), loc="lower center", ncol=4, fontsize=8,
               frameon=False)
    fig.suptitle(title or "Speed against accuracy: lower left is better", fontsize=12)
    fig.tight_layout(rect=(0, 0.12, 1, 0.95))
    for ax, items in names:
        _labels(ax, items)
    path = pathlib.Path(path)
    base = path.with_suffix("")
    base.parent.mkdir(parents=True, exist_ok=True)
    out = [base.with_suffix(".png"), base.with_suffix(".svg")]
    fig.savefig(out[0], dpi=130)
    fig.savefig(out[1])
    plt.close(fig)
    return out


def _labels(ax, items: list) -> None:
    """Name each point (``(x, y, text)``) beside it, trying a few places around it so that no
    two names overlap and none leaves the axes (the first such place; the first tried if none
    is)."""
    fig = ax.figure
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    placed = []
    frame = ax.get_window_extent(renderer)
    offsets = [(5, 4), (5, -11), (-5, 4), (-5, -11), (5, 14), (5, -21), (-5, 14), (-5, -21)]
    for x, y, text in sorted(items, key=lambda t: (t[0], t[1])):
        for dx, dy in offsets:
            t = ax.annotate(text, (x, y), xytext=(dx, dy), textcoords="offset points",
                            fontsize=7, color="#333333", ha="left" if dx > 0 else "right")
            box = t.get_window_extent(renderer)
            inside = (frame.x0 <= box.x0 and box.x1 <= frame.x1 and frame.y0 <= box.y0
                      and box.y1 <= frame.y1)
            if inside and not any(box.overlaps(b) for b in placed):
                break
            t.remove()
        else:
            t = ax.annotate(text, (x, y), xytext=offsets[0], textcoords="offset points",
                            fontsize=7, color="#333333")
            box = t.get_window_extent(renderer)
        placed.append(box)
