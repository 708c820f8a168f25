"""The speed-vs-accuracy chart: time per scene (log) against the out-of-distribution error,
one point per method and batch size, the Pareto front drawn, the paper's reported point marked
as a reference (not a measurement of ours).
"""

from __future__ import annotations

import pathlib

import numpy as np

FAMILIES = {  # family: colour
    "FEM": "#444444",
    "linear FEM": "#1f77b4",
    "UV-UNet": "#d62728",
    "GNN": "#2ca02c",
    "Naive": "#9467bd",
    "other": "#8c564b",
}
LABEL_STYLE = {"fontsize": 7, "color": "#333333"}
PAPER_POINT = {
    "seconds": 0.002,
    "rel_mee": 5.57,
    "label": "paper's UV-UNet (reported: A6000 GPU, its data)",
}


def family(name: str) -> str:
    """The family of a set-up from its name (for the colour)."""
    low = name.lower()
    for key, fam in (
        ("linear", "linear FEM"),
        ("fem", "FEM"),
        ("unet", "UV-UNet"),
        ("gnn", "GNN"),
        ("naive", "Naive"),
    ):
        if key in low:
            return fam
    return "other"


def pareto(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Indices of the points no other point beats on both ``x`` and ``y`` (lower is better),
    ordered by ``x``.
    """
    order = np.lexsort((y, x))
    front, best = [], np.inf
    for i in order:
        if y[i] < best:
            front.append(i)
            best = y[i]
    return np.asarray(front, dtype=int)


PANELS = (("in", "in distribution"), ("out", "out of distribution (pooled)"))
"""The chart's panels: the key of each point's error, and the panel's words."""
PAPER_FEM = {
    "seconds": 84.0,
    "spread": (84.0 - 53.4, 84.0 + 53.4),
    "label": "paper's FEM, 84 ± 53 s (reported: i7-12700K, one thread)",
}
"""The paper's FEM time per simulation (Runtime Evaluation: 84 ± 53.4 s), its truth."""


def speed_accuracy(points: list[dict], path, title: str = "") -> list[pathlib.Path]:
    """Draw ``points`` into ``path`` as PNG and SVG; returns the files written. Each point:
    ``label``, ``batch``, ``seconds`` per scene and ``spread`` (its quartiles, or ``None``),
    and per panel (``in``, ``out``) ``{"rel_mee": %, "ci": %}`` or ``None``; a point with
    ``truth`` (the FEM the data was made with) sits on the panels' floor.
    """
    import matplotlib  # deferred: pictures only

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # deferred: pictures only
    import matplotlib.ticker  # deferred: pictures only
    from matplotlib.lines import Line2D  # deferred: pictures only

    if not points:
        raise ValueError("no points to chart")
    fig, axes = plt.subplots(1, 2, figsize=(13, 5.6), dpi=130)  # laid out as saved
    x = np.array([p["seconds"] * 1e3 for p in points])
    spread = np.array(
        [
            [x[i] - 1e3 * p["spread"][0], 1e3 * p["spread"][1] - x[i]]
            if p.get("spread")
            else [0.0, 0.0]
            for i, p in enumerate(points)
        ]
    ).T
    truths = [i for i, p in enumerate(points) if p.get("truth")]
    names = []  # (axes, points to name) once laid out
    for ax, (key, what) in zip(axes, PANELS):
        y = np.array([p[key]["rel_mee"] if p.get(key) else np.nan for p in points])
        ci = np.array([p[key]["ci"] if p.get(key) else 0.0 for p in points])
        ok = np.isfinite(x) & np.isfinite(y) & (x > 0) & (y > 0)
        for i in np.flatnonzero(ok):
            colour = FAMILIES[family(points[i]["label"])]
            ax.errorbar(
                x[i],
                y[i],
                xerr=spread[:, i : i + 1],
                yerr=[[min(ci[i], 0.95 * y[i])], [ci[i]]],
                fmt="o" if points[i]["batch"] == 1 else "s",
                ms=6.5,
                color=colour,
                mec="white",
                mew=0.6,
                elinewidth=0.9,
                ecolor=colour,
                alpha=0.95,
                zorder=3,
            )
        for label in {points[i]["label"] for i in np.flatnonzero(ok)}:  # its batch sizes
            mine = sorted((x[i], y[i]) for i in np.flatnonzero(ok) if points[i]["label"] == label)
            if len(mine) > 1:
                ax.plot(*zip(*mine), c=FAMILIES[family(label)], lw=0.8, alpha=0.4, zorder=2)
        for batched, style in ((False, "-"), (True, "--")):
            idx = [i for i in np.flatnonzero(ok) if (points[i]["batch"] > 1) == batched]
            front = np.asarray(idx, dtype=int)[pareto(x[idx], y[idx])] if idx else []
            if len(front) > 1:
                ax.step(x[front], y[front], where="post", c="#999999", lw=1.1, ls=style, zorder=2)
        if key == "out":
            ax.scatter(
                [PAPER_POINT["seconds"] * 1e3],
                [PAPER_POINT["rel_mee"]],
                marker="*",
                s=160,
                facecolors="none",
                edgecolors="black",
                zorder=4,
            )
        ax.set_xscale("log")
        ax.set_yscale("log")
        low = y[ok].min() / 2.6 if ok.any() else 0.1
        floor = low * 1.35  # the truth's row, under every measured error
        ax.set_ylim(low, (y[ok].max() * 1.5) if ok.any() else 100)
        xs = list(x[ok]) + [x[i] for i in truths] + [1e3 * PAPER_FEM["spread"][1]]
        ax.set_xlim(min(xs) / 1.6, max(xs) * 6)
        truth_x = [x[i] for i in truths]
        ax.errorbar(
            truth_x + [1e3 * PAPER_FEM["seconds"]],
            [floor] * (len(truths) + 1),
            xerr=np.concatenate(
                [
                    spread[:, truths],
                    1e3
                    * np.array(
                        [
                            [PAPER_FEM["seconds"] - PAPER_FEM["spread"][0]],
                            [PAPER_FEM["spread"][1] - PAPER_FEM["seconds"]],
                        ]
                    ),
                ],
                axis=1,
            ),
            fmt="none",
            ecolor="#444444",
            elinewidth=0.9,
            zorder=3,
        )
        ax.scatter(truth_x, [floor] * len(truths), marker="D", s=34, c="#444444", zorder=4)
        ax.scatter(
            [1e3 * PAPER_FEM["seconds"]],
            [floor],
            marker="D",
            s=34,
            facecolors="white",
            edgecolors="#444444",
            zorder=4,
        )
        ax.axhline(floor * 1.25, c="#cccccc", lw=0.8, zorder=1)
        ax.text(
            0.01,
            floor * 1.2,
            "the truth (no error of its own)",
            transform=ax.get_yaxis_transform(),
            fontsize=7,
            color="#666666",
            va="top",
        )
        ax.set_xlabel("time per scene, ms (log; this CPU unless marked)")
        ax.set_ylabel("relative MEE, % (log)")
        ax.set_title(what, fontsize=10)
        ax.grid(True, which="both", alpha=0.25)
        fmt = matplotlib.ticker.FuncFormatter(
            lambda v, _: f"{v / 1e3:g}k" if v >= 1e3 else f"{v:g}"
        )  # 1k, 2k: ticks keep apart
        for axis, subs in ((ax.xaxis, (1.0,)), (ax.yaxis, (1.0, 2.0, 5.0))):  # labelled ticks
            axis.set_major_locator(matplotlib.ticker.LogLocator(subs=subs))
            axis.set_major_formatter(fmt)
            axis.set_minor_formatter(matplotlib.ticker.NullFormatter())
        for at, text in [(x[i], points[i]["label"]) for i in truths] + [
            (1e3 * PAPER_FEM["seconds"], "paper's FEM")
        ]:  # the truth's row is theirs alone: named right above each
            ax.annotate(
                text,
                (at, floor),
                xytext=(0, 6),
                textcoords="offset points",
                ha="center",
                **LABEL_STYLE,
            )
        items = [
            (x[i], y[i], points[i]["label"]) for i in np.flatnonzero(ok) if points[i]["batch"] == 1
        ]
        marks = [(x[i], y[i]) for i in np.flatnonzero(ok)]
        names.append((ax, items, marks))
    legend = [
        Line2D([], [], ls="", marker="o", color=c, mec="white", ms=7, label=f)
        for f, c in FAMILIES.items()
        if any(family(p["label"]) == f for p in points)
    ]
    legend += [
        Line2D([], [], ls="", marker="o", color="#888888", ms=7, label="batch 1"),
        Line2D([], [], ls="", marker="s", color="#888888", ms=7, label="batch 64"),
        Line2D([], [], c="#999999", ls="-", label="Pareto front, batch 1"),
        Line2D([], [], c="#999999", ls="--", label="Pareto front, batch 64"),
        Line2D(
            [],
            [],
            ls="",
            marker="D",
            color="#444444",
            label="our FEM at the data's mesh (the truth)",
        ),
        Line2D([], [], ls="", marker="D", mfc="white", color="#444444", label=PAPER_FEM["label"]),
        Line2D(
            [], [], ls="", marker="*", mfc="none", color="black", ms=11, label=PAPER_POINT["label"]
        ),
    ]
    fig.legend(handles=legend, loc="lower center", ncol=4, fontsize=8, frameon=False)
    fig.suptitle(
        (title or "Speed against accuracy: lower left is better")
        + "\nbars: quartiles of the time over repeats; 95 % interval of the mean error over the "
        "test scenes",
        fontsize=11,
    )
    fig.tight_layout(rect=(0, 0.14, 1, 0.93))
    for ax, items, markers in names:
        _labels(ax, items, markers)
    path = pathlib.Path(path)
    base = path.with_suffix("")
    base.parent.mkdir(parents=True, exist_ok=True)
    out = [base.with_suffix(".png"), base.with_suffix(".svg")]
    fig.savefig(out[0], dpi=130)
    fig.savefig(out[1])
    plt.close(fig)
    return out


def _nearest(box, own, markers: list, ax) -> bool:
    """Whether the name in display box ``box`` lies nearer its own point ``own`` (data) than
    any other marker (so that a reader pairs them right).
    """

    def gap(p):
        cx, cy = ax.transData.transform(p)
        return np.hypot(max(box.x0 - cx, 0, cx - box.x1), max(box.y0 - cy, 0, cy - box.y1))

    mine = gap(own)
    return all(gap(m) > mine for m in markers if tuple(m) != tuple(own))


def _labels(ax, items: list, markers: list | None = None) -> None:
    """Name each point (``(x, y, text)``) beside it where the name overlaps no other name, no
    marker and stays inside the axes; the names that find no such place line up in a column
    to the right of their points, each joined to its point by a thin leader line, in the
    points' vertical order (so the lines do not cross), right of every marker (``markers``,
    ``(x, y)``: all the panel's points, unnamed ones too) at their height. A name beside its
    point that the column covers looks for another place around its point (more of them),
    or joins the column.
    """
    from matplotlib.text import Text  # deferred: pictures only

    fig = ax.figure
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    markers = [(x, y) for x, y, _ in items] + list(markers or [])
    beside, crowded = _beside(ax, items, markers, [], renderer, NEAR)
    for last in (False, False, True):
        column = _column(ax, crowded, markers)
        fig.canvas.draw()  # puts the column's names in place
        boxes = [
            Text.get_window_extent(a, renderer).padded(2 * fig.dpi / 72) for a in column
        ]  # the names, not their leaders
        clash = [
            b for b in beside if any(b[0].get_window_extent(renderer).overlaps(c) for c in boxes)
        ]
        if not clash or last:  # the last round's column stays
            return
        for a, _, _ in clash:
            a.remove()
        beside = [b for b in beside if b not in clash]
        again, still = _beside(
            ax,
            [item for _, item, _ in clash],
            markers,
            [b[0].get_window_extent(renderer) for b in beside] + boxes,
            renderer,
            NEAR + FARTHER,
        )
        beside += again
        if not still:
            return
        for a in column:  # no other place: into the column
            a.remove()
        crowded += still


NEAR = ((5, 4), (5, -11), (-5, 4), (-5, -11))  # name offsets from its point, points
FARTHER = (
    (0, 8),
    (0, -15),
    (5, 12),
    (-5, 12),
    (5, -19),
    (-5, -19),
    (5, 22),
    (-5, 22),
    (5, -29),
    (-5, -29),
)


def _beside(
    ax, items: list, markers: list, obstacles: list, renderer, offsets: tuple
) -> tuple[list, list]:
    """Put each name beside its point, at the first of ``offsets`` (points) where it overlaps
    nothing (markers, names, display boxes ``obstacles``) and lies nearer its point than any
    other; returns (``(annotation, item, offset)`` for the names placed, the ``(x, y, text)``
    items that found no place).
    """
    from matplotlib.transforms import Bbox  # deferred: pictures only

    frame = ax.get_window_extent(renderer)
    scale = ax.figure.dpi / 72.0  # points -> display pixels
    names = list(obstacles)
    marks = []
    for x, y in markers:  # names keep off the markers
        cx, cy = ax.transData.transform((x, y))
        marks.append(Bbox.from_bounds(cx - 4 * scale, cy - 4 * scale, 8 * scale, 8 * scale))
    done, crowded = [], []
    for item in sorted(items, key=lambda t: (t[0], t[1])):
        x, y, text = item
        for dx, dy in offsets:
            t = ax.annotate(
                text,
                (x, y),
                xytext=(dx, dy),
                textcoords="offset points",
                ha="left" if dx > 0 else "right" if dx < 0 else "center",
                **LABEL_STYLE,
            )
            box = t.get_window_extent(renderer)
            inside = (
                frame.x0 <= box.x0
                and box.x1 <= frame.x1
                and frame.y0 <= box.y0
                and box.y1 <= frame.y1
            )
            air = box.padded(2 * scale)  # names keep a little apart
            if (
                inside
                and not any(box.overlaps(b) for b in marks)
                and not any(air.overlaps(b) for b in names)
                and _nearest(box, (x, y), markers, ax)
            ):
                names.append(box)
                done.append((t, item, (dx, dy)))
                break
            t.remove()
        else:
            crowded.append(item)
    return done, crowded


def _column(ax, crowded: list, markers: list) -> list:
    """The names of ``crowded`` (``(x, y, text)``) in a column right of their points and of
    the markers at their height (left if there is no room), joined to them by leader lines;
    returns the annotations.
    """
    if not crowded:
        return []
    frame = ax.get_window_extent(ax.figure.canvas.get_renderer())
    scale = ax.figure.dpi / 72.0
    pix = [ax.transData.transform((x, y)) for x, y, _ in crowded]
    step = 11 * scale
    top, bottom = max(p[1] for p in pix) + step, min(p[1] for p in pix) - len(pix) * step
    reach = max(p[0] for p in pix) + 100 * scale  # the crowd's own neighbourhood
    beside = [
        m[0]
        for m in (ax.transData.transform(m) for m in markers)
        if bottom <= m[1] <= top and m[0] <= reach
    ]
    column = max([p[0] for p in pix] + beside) + 14 * scale  # right of the markers there
    order = np.argsort([-p[1] for p in pix])  # top to bottom
    ys, last = {}, np.inf
    for i in order:
        ys[i] = min(pix[i][1] + 6 * scale, last - step)  # a little above: the leader slants
        last = ys[i]
    low = min(ys.values()) - frame.y0 - 4 * scale  # lift the column into the axes
    if low < 0:
        ys = {i: v - low for i, v in ys.items()}
    side = "left"
    if column + 110 * scale > frame.x1:  # no room on the right: the left
        column, side = min(p[0] for p in pix) - 14 * scale, "right"
    to_data = ax.transData.inverted()
    out = []
    for i, (x, y, text) in enumerate(crowded):
        at = to_data.transform((column, ys[i]))
        out.append(
            ax.annotate(
                text,
                (x, y),
                xytext=tuple(at),
                textcoords="data",
                ha=side,
                va="center",
                arrowprops={
                    "arrowstyle": "-",
                    "color": "#777777",
                    "lw": 0.6,
                    "shrinkA": 2,
                    "shrinkB": 4 * scale,
                },
                **LABEL_STYLE,
            )
        )
    return out
