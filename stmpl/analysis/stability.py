"""The stability sweep: where each method stops being right, and how.

From a base scene (a disk on the arm), one axis at a time is pushed from easy to past where the
FEM stops: the total force, the mean pressure (force over a fixed disk), the load's size at a
fixed pressure (a fingertip to a wide patch), the thickness, the place (across the UV seam, up to
the open rims), the number of simultaneous contacts and how much the thickness varies under
the load. At every point the FEM solves the scene (its failures counted with the reason and the
time it took to fail) and every predictor answers it: its relative MEE and peak error against
the FEM, whether it flagged the scene as outside its envelope and whether its answer was
physically possible. Results are cached per point (by the scene's content, the FEM set-up and the
predictors' digests; the flags are not cached but follow each model's envelope as it is today);
a run keeps only its own points (a model retrained leaves no stale records behind), and the FEM's
answers are cached apart, so new models are measured without solving the FEM again:
``stmpl ablate configs/ablation/stability.yaml`` runs it and draws one picture per axis and the
envelope map.
"""

from __future__ import annotations

import hashlib
import json
import pathlib
import textwrap
import time
import warnings

import numpy as np
from tqdm import tqdm

from stmpl import config as checked
from stmpl import loads, predictor, tissue
from stmpl.body.model import default_cache_dir
from stmpl.body.spec import part_from_spec
from stmpl.files import atomic_savez, atomic_write_text
from stmpl.metrics import sample_metrics
from stmpl.pipeline.spec import key as spec_key
from stmpl.pipeline.spec import label, predictor_from_spec
from stmpl.predictor import ImpossibleAnswer, OutsideEnvelope, PredictionFailed
from stmpl.scene import Scene
from stmpl.table import markdown
from stmpl.viz.chart import FAMILIES, family

DEFAULTS = {
    "name": None,
    "kind": "stability",
    "body": {"model": "anny"},
    "part": "left_arm",
    "predictors": [],
    "fem": {"res": "reference", "levels": 4},
    "base": {"radius": 0.02, "total": 0.3, "thickness_mm": 7.5, "uv": [0.5, 0.5]},
    "axes": {},
    "out": None,
}
LINES = ("-", (0, (5, 2)), "-.", (0, (1, 1.2)))
"""Line styles that tell apart the models of one family (which share its colour)."""
MARKERS = ("o", "^", "s", "D")

AXES = {
    "force": ("total force, N", "total"),
    "pressure": ("mean pressure on a 2 cm disk, kPa", "pressure_kpa"),
    "size": ("disk radius at the base pressure, mm", "radius_mm"),
    "thickness": ("tissue thickness, mm", "thickness_mm"),
    "seam": ("a disk across the UV seam, position along it (0-1)", "at"),
    "rim": ("a disk along the limb, 0 = proximal rim, 1 = distal rim", "along"),
    "contacts": ("simultaneous contacts (1.5 cm disks in a row, the force shared)", "count"),
    "variation": (
        "thickness ramp through the load, mm per 10 cm (kept within 5-10 mm)",
        "slope_mm",
    ),
}


LOG_AXES = ("force", "pressure")
"""Axes drawn on a log scale (they span two decades)."""


def read_config(source) -> dict:

    cfg = checked.read(source, DEFAULTS, "stability config")
    if not cfg["predictors"]:
        raise ValueError("predictors must list at least one predictor spec (zoo:NAME, ...)")
    if not isinstance(cfg["axes"], dict) or not cfg["axes"]:
        raise ValueError(f"axes must name at least one of {sorted(AXES)}")
    for a, v in cfg["axes"].items():
        if a not in AXES:
            raise ValueError(f"unknown stability axis {a!r}; use {sorted(AXES)}")
        if (
            not isinstance(v, list)
            or not v
            or any(isinstance(x, bool) or not isinstance(x, (int, float)) for x in v)
        ):
            raise ValueError(f"axes.{a} must be a list of numbers, got {v!r}")
    cfg["out"] = cfg["out"] or f"reports/{cfg['name']}"
    return cfg


def scene_at(part, base: dict, axis: str, value: float):
    """The base scene with ``axis`` set to ``value``."""
    r, total, t = base["radius"], base["total"], base["thickness_mm"] * 1e-3
    uv = tuple(base["uv"])
    thick = tissue.constant(part, t)
    if axis == "force":
        load = loads.disk(part, uv=uv, radius=r, total=value)
    elif axis == "pressure":
        area = loads.disk(part, uv=uv, radius=r, total=1.0).area
        load = loads.disk(part, uv=uv, radius=r, total=value * 1e3 * area)
    elif axis == "size":
        p0 = total / loads.disk(part, uv=uv, radius=r, total=1.0).area
        unit = loads.disk(part, uv=uv, radius=value * 1e-3, total=1.0)
        load = loads.disk(part, uv=uv, radius=value * 1e-3, total=p0 * unit.area)
    elif axis == "thickness":
        load = loads.disk(part, uv=uv, radius=r, total=total)
        thick = tissue.constant(part, value * 1e-3)
    elif axis == "seam":
        load = loads.seam_disk(part, at=value, radius=r, total=total)
    elif axis == "rim":  # the base's side of the limb, moved along it
        load = loads.disk(part, at=_side_vertex(part, uv, value), radius=r, total=total)
    elif axis == "contacts":  # 1.5 cm disks in a row along the limb
        n = int(value)
        alongs = np.linspace(0.3, 0.7, n) if n > 1 else [None]
        parts = [
            loads.disk(part, uv=uv, radius=0.015, total=total)
            if a is None
            else loads.disk(
                part, at=_side_vertex(part, uv, float(a)), radius=0.015, total=total / n
            )
            for a in alongs
        ]
        load = parts[0] if n == 1 else loads.combine(part, *parts)
    elif axis == "variation":
        load = loads.disk(part, uv=uv, radius=r, total=total)
        centre = part.axial[load.vertices].mean()
        thick = tissue.check(
            part, np.clip(t + value * 1e-2 * (part.axial - centre), 0.005, 0.010)
        )  # the range the models know
    else:
        raise ValueError(f"unknown axis {axis!r}")
    return Scene.from_load(part, thick, load, axis=axis, value=float(value))


def _side_vertex(part, uv, along: float) -> int:
    """The vertex at fraction ``along`` of the limb on the same side as chart point ``uv``."""
    p0 = loads.place(part, uv=uv).position
    s = part.axial
    k0 = int(np.argmin(np.linalg.norm(part.vertices - p0, axis=1)))
    c0, d0, _ = part.limb_frame(float((s[k0] - s.min()) / (s.max() - s.min())))
    radial = (p0 - c0) - ((p0 - c0) @ d0) * d0
    c, _, s0 = part.limb_frame(along)
    near = np.abs(s - s0) <= np.abs(s - s0).min() + 0.01
    dist = np.linalg.norm(part.vertices - (c + radial), axis=1)
    return int(np.flatnonzero(near)[np.argmin(dist[near])])


def _fem_answer(fem, scene, key: str):
    """The FEM's displacement ``(N, 3)`` m of ``scene`` (``None`` if the solve failed) and its
    record (ok, seconds, deepest_mm or reason). Kept in stmpl's cache directory (``sweep/``) by
    ``key`` (the part, the FEM set-up and the scene's content), so that a sweep re-run for new
    models measures the models and does not solve the FEM again.
    """
    path = default_cache_dir() / "sweep" / f"{key}.npz"
    if path.is_file():
        try:
            with np.load(path) as z:
                rec = json.loads(str(z["record"]))
                return (z["displacement"] if rec["ok"] else None), rec
        except (OSError, ValueError, KeyError):
            pass  # a broken cache file: solve again
    t0 = time.perf_counter()
    try:
        d = fem.predict(scene)
        u = d.displacement
        rec = {
            "ok": True,
            "seconds": time.perf_counter() - t0,
            "deepest_mm": 1e3 * float(d.magnitude.max()),
        }
    except PredictionFailed as e:
        u = None
        rec = {"ok": False, "seconds": time.perf_counter() - t0, "reason": str(e)}
    atomic_savez(
        path,
        {
            "record": np.array(json.dumps(rec)),
            "displacement": u if u is not None else np.zeros((0, 3)),
        },
    )
    return u, rec


def _key(*parts) -> str:
    return hashlib.sha256(json.dumps(parts, sort_keys=True, default=str).encode()).hexdigest()[:12]


def run(config, progress: bool = True) -> dict:
    """Run (or complete) a sweep; returns ``{"points": [...], "out": folder}``."""
    cfg = read_config(config)
    out = pathlib.Path(cfg["out"])
    out.mkdir(parents=True, exist_ok=True)
    cache_path = out / "points.json"
    cache = json.loads(cache_path.read_text()) if cache_path.is_file() else {}
    part = part_from_spec(cfg["body"], cfg["part"])
    fem = predictor.create("fem", **cfg["fem"])
    preds = {label(s): predictor_from_spec(s) for s in cfg["predictors"]}
    models = {label(s): spec_key(s) for s in sorted(cfg["predictors"])}  # their digests
    todo = [(a, float(v)) for a, vals in cfg["axes"].items() for v in vals]
    bar = None
    if progress:
        bar = tqdm(total=len(todo), unit="point", desc=f"sweep {cfg['name']}", dynamic_ncols=True)
    points, used = [], set()
    for axis, value in todo:
        try:
            scene = scene_at(part, cfg["base"], axis, value)
        except ValueError as e:  # e.g. a fingertip between this mesh's vertices
            points.append({"axis": axis, "value": value, "skipped": str(e)})
            if bar is not None:
                bar.update(1)
            continue
        content = hashlib.sha256(scene.force.tobytes() + scene.thickness.tobytes()).hexdigest()
        key = _key(part.fingerprint, cfg["fem"], axis, value, models, content)  # what decides
        if key not in cache:
            rec = {
                "axis": axis,
                "value": value,
                "total": scene.total_force,
                "load": scene.load.to_dict() if scene.load is not None else None,
            }
            truth, rec["fem"] = _fem_answer(fem, scene, _key(part.fingerprint, cfg["fem"], content))
            rec["predictors"] = {}
            for name, p in preds.items():
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore", OutsideEnvelope)
                    warnings.simplefilter("ignore", ImpossibleAnswer)
                    try:
                        d = p.predict(scene)
                    except (ValueError, PredictionFailed) as e:  # e.g. a thickness it lacks
                        rec["predictors"][name] = {"refused": str(e)}
                        continue
                env = d.info.get("envelope")
                r = {
                    "inside": None if env is None else env["inside"],
                    "outside": None if env is None else env["outside"],
                    "physical": d.info["physical"],
                    "seconds": d.info["seconds"],
                    "deepest_mm": 1e3 * float(d.magnitude.max()),
                }
                if truth is not None:
                    m = sample_metrics(truth, d.displacement)
                    r.update(rel_mee=m["rel_mee"], peak_err=m["peak_err"], max_err=m["max_err"])
                rec["predictors"][name] = r
            cache[key] = rec
            atomic_write_text(cache_path, json.dumps(cache, indent=1, sort_keys=True))
        rec = cache[key]
        used.add(key)
        for name, p in preds.items():  # the flags follow the envelope as it is today
            r = rec["predictors"].get(name, {})
            if "refused" not in r and p.envelope is not None:
                why = p.envelope.reasons(scene)
                r["inside"], r["outside"] = not why, why
        points.append(rec)
        if bar is not None:
            bar.update(1)
    if bar is not None:
        bar.close()
    # this sweep's points only (a retrained model's records go), their flags as of today
    atomic_write_text(
        cache_path, json.dumps({k: cache[k] for k in sorted(used)}, indent=1, sort_keys=True)
    )
    figures(cfg, [p for p in points if "skipped" not in p], out)
    report(cfg, points, out)
    return {"points": points, "out": out}


def verdict(r: dict) -> str:
    """A predictor's answer at a point: ``refused``, ``impossible``, ``no FEM``, or its relative
    MEE against the FEM: ``<=1 %``, ``<=5 %``, ``>5 %`` (the peak is judged apart:
    :func:`peak_off`).
    """
    if "refused" in r:
        return "refused"
    if not r["physical"]:
        return "impossible"
    if "rel_mee" not in r:
        return "no FEM"
    return "<=1 %" if r["rel_mee"] <= 1 else "<=5 %" if r["rel_mee"] <= 5 else ">5 %"


def peak_off(r: dict, limit: float = 5.0) -> bool:
    """Whether the predicted deepest displacement is off the FEM's by more than ``limit`` %."""
    return "peak_err" in r and abs(r["peak_err"]) > limit


def figures(cfg, points: list, out: pathlib.Path) -> list:
    """One picture per axis (relative MEE and |peak error| per predictor against the axis,
    FEM failures marked with the seconds they took) and the envelope map.
    """
    import matplotlib  # deferred: pictures only

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # deferred: pictures only

    files = []
    names = sorted({n for p in points for n in p["predictors"]})
    for axis in cfg["axes"]:
        pts = [p for p in points if p["axis"] == axis]
        if not pts:  # every point of the axis was skipped
            continue
        x = np.array([p["value"] for p in pts])
        inside_of = {
            n: np.array(
                [p["predictors"].get(n, {}).get("inside") is not False for p in pts], dtype=bool
            )
            for n in names
        }
        fig, axes = plt.subplots(1, 2, figsize=(12, 4.4))
        rank = {n: [m for m in names if family(m) == family(n)].index(n) for n in names}
        for ax, metric, what in (
            (axes[0], "rel_mee", "relative MEE against the FEM, %"),
            (axes[1], "peak_err", "|peak error| against the FEM, %"),
        ):
            for n in names:
                y = np.array([abs(p["predictors"].get(n, {}).get(metric, np.nan)) for p in pts])
                inside = inside_of[n]
                c = FAMILIES[family(n)]  # a family's colour; its models apart
                ls, mk = LINES[rank[n] % len(LINES)], MARKERS[rank[n] % len(MARKERS)]
                ax.plot(x, y, ls=ls, marker=mk, c=c, lw=1.2, ms=5.5, mfc=c, label=n)
                ax.scatter(
                    x[~inside],
                    y[~inside],
                    marker=mk,
                    facecolors="white",
                    edgecolors=c,
                    s=30,
                    zorder=3,
                )
            for lim, ls in ((1, ":"), (5, "--")):
                ax.axhline(lim, c="#888888", lw=0.8, ls=ls)
            fails = [p for p in pts if not p["fem"]["ok"]]
            for p in fails:
                ax.axvline(p["value"], c="#cc0000", lw=0.8, alpha=0.5)
            ax.set_yscale("log")  # 1-2-5 ticks, labelled, as on the chart
            ax.yaxis.set_major_locator(matplotlib.ticker.LogLocator(subs=(1.0, 2.0, 5.0)))
            ax.yaxis.set_major_formatter(matplotlib.ticker.FormatStrFormatter("%g"))
            ax.yaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
            if axis in LOG_AXES:  # forces from 0.05 to 5 N
                ax.set_xscale("log")
                ax.xaxis.set_major_formatter(matplotlib.ticker.FormatStrFormatter("%g"))
            if axis == "contacts":
                ax.xaxis.set_major_locator(matplotlib.ticker.MaxNLocator(integer=True))
            if fails and ax is axes[0]:
                _fem_fails(ax, fails[0])
            ax.set_xlabel(AXES[axis][0])
            ax.set_ylabel(what + " (log)")
            ax.grid(True, which="both", alpha=0.25)
        handles, labels = axes[0].get_legend_handles_labels()  # below the panels: no line hidden
        fig.legend(
            handles,
            labels,
            loc="lower center",
            ncol=len(labels),
            fontsize=8,
            frameon=False,
            title="filled: inside its envelope; open: outside",
            title_fontsize=7,
        )
        fig.suptitle(
            f"Stability along {axis}: grey lines at 1 % and 5 %; red lines: the FEM fails",
            fontsize=11,
        )
        fig.tight_layout(rect=(0, 0.1, 1, 1))
        f = out / f"stability_{axis}.png"
        fig.savefig(f, dpi=120)
        plt.close(fig)
        files.append(f)
    files.append(envelope_map(points, names, out / "envelope_map.png"))
    return files


def _fem_fails(ax, f0: dict) -> None:
    """Say where the FEM starts failing, why and how fast: in the failing region to the right of
    the first failure when it has room (no method has an error there to hide), else above the
    panel.
    """
    why = textwrap.shorten(f0["fem"]["reason"].split(": ", 1)[-1], 60, placeholder="...")
    text = f"FEM fails from here after {f0['fem']['seconds']:.1f} s:\n" + "\n".join(
        textwrap.wrap(why, 32)
    )
    x = ax.transScale.transform((f0["value"], 1.0))[0]  # where on the axis, 0..1
    lo, hi = (ax.transScale.transform((v, 1.0))[0] for v in ax.get_xlim())
    if (hi - x) / (hi - lo) > 0.3:
        ax.annotate(
            text,
            (f0["value"], 0.5),
            xycoords=("data", "axes fraction"),
            fontsize=7,
            color="#cc0000",
            xytext=(4, 0),
            textcoords="offset points",
            va="center",
        )
    else:
        ax.set_title(
            f"FEM fails from {f0['value']:g} after {f0['fem']['seconds']:.1f} s: {why}",
            fontsize=7,
            color="#cc0000",
            loc="right",
        )


COLOURS = {
    "<=1 %": "#2ca02c",
    "<=5 %": "#ffbf00",
    ">5 %": "#d62728",
    "impossible": "#5a0000",
    "refused": "#bbbbbb",
    "no FEM": "#ffffff",
}


def envelope_map(points: list, names: list, path) -> pathlib.Path:
    """Rows: the sweep's points (axis = value); columns: predictors; colour: relative MEE within
    1 %, within 5 %, worse, impossible, refused, or no FEM answer to judge by; a cross: outside
    the predictor's envelope (it warned); a number: the peak error (%) where it is off by more
    than 5 %.
    """
    import matplotlib  # deferred: pictures only

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # deferred: pictures only
    from matplotlib.patches import Patch  # deferred: pictures only

    fig, ax = plt.subplots(figsize=(1.6 + 1.5 * len(names), 0.9 + 0.22 * len(points)))
    for i, p in enumerate(points):
        for j, n in enumerate(names):
            r = p["predictors"].get(n, {"refused": ""})
            v = verdict(r)
            ax.add_patch(plt.Rectangle((j, i), 1, 1, fc=COLOURS[v], ec="white"))
            if r.get("inside") is False:
                ax.plot([j + 0.3, j + 0.7], [i + 0.3, i + 0.7], c="black", lw=1)
                ax.plot([j + 0.3, j + 0.7], [i + 0.7, i + 0.3], c="black", lw=1)
            if peak_off(r):
                ax.text(
                    j + 0.9, i + 0.5, f"{r['peak_err']:+.0f}", ha="right", va="center", fontsize=6
                )
        if not p["fem"]["ok"]:
            ax.text(
                len(names) + 0.1, i + 0.5, "FEM fails", va="center", fontsize=7, color="#cc0000"
            )
    ax.set_xlim(0, len(names) + 1)
    ax.set_ylim(len(points), 0)
    ax.set_xticks(np.arange(len(names)) + 0.5, names, fontsize=8)
    ax.set_yticks(
        np.arange(len(points)) + 0.5, [f"{p['axis']} = {p['value']:g}" for p in points], fontsize=7
    )
    ax.tick_params(length=0)
    for s in ax.spines.values():
        s.set_visible(False)
    ax.legend(
        handles=[Patch(fc=c, ec="#999999", label=k) for k, c in COLOURS.items()],
        loc="upper left",
        bbox_to_anchor=(1.0, 1.0),
        fontsize=7,
        title="relative MEE vs the FEM\nx = outside its envelope\n+14 = peak off by more than 5 %",
        title_fontsize=7,
    )
    ax.set_title("Where each method can be trusted", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return pathlib.Path(path)


def _cells(p: dict, names: list[str]) -> list[str]:
    """One sweep point's cell per predictor: relative MEE / peak error, or the deepest
    displacement without the FEM, with its flags.
    """
    cells = []
    for n in names:
        r = p["predictors"].get(n, {})
        if "refused" in r:
            cells.append("refused")
            continue
        c = (
            f"{r['rel_mee']:.2f} / {r['peak_err']:+.1f}"
            if "rel_mee" in r
            else f"{r['deepest_mm']:.2f} mm"
        )
        if r.get("inside") is False:
            c += " out"
        if not r["physical"]:
            c += " IMPOSSIBLE"
        cells.append(c)
    return cells


def report(cfg, points: list, out: pathlib.Path) -> pathlib.Path:
    """``stability.md``: per axis, the FEM's outcome and each predictor's errors and flags."""
    names = sorted({n for p in points for n in p.get("predictors", {})})
    lines = [
        f"# Stability sweep: {cfg['name']}\n",
        f"Base: a disk of {cfg['base']['radius'] * 1e3:g} mm radius, "
        f"{cfg['base']['total']:g} N, {cfg['base']['thickness_mm']:g} mm of tissue at "
        f"chart {tuple(cfg['base']['uv'])}; FEM {cfg['fem']}. Cells: relative MEE / peak "
        "error (%) against the FEM; `out` = outside the predictor's envelope (it warned), "
        "`IMPOSSIBLE` = the skin moved in past where the gel buckles (and the FEM gives no "
        "answer).\n",
        "![envelope map](envelope_map.png)\n",
    ]
    for axis in cfg["axes"]:
        shown = any("skipped" not in q for q in points if q["axis"] == axis)
        lines.append(
            f"## {axis}: {AXES[axis][0]}\n"
            + (f"\n![{axis}](stability_{axis}.png)\n" if shown else "")
        )
        rows = []
        for p in (q for q in points if q["axis"] == axis):
            if "skipped" in p:
                why = f"not made on this mesh: {p['skipped'].split(' (')[0]}"
                rows.append([f"{p['value']:g}", "", why] + [""] * len(names))
                continue
            f = p["fem"]
            fem = (
                f"{f['deepest_mm']:.3f} mm, {f['seconds']:.1f} s"
                if f["ok"]
                else f"fails after {f['seconds']:.1f} s: {f['reason'].split(': ', 1)[-1]}"
            )
            rows.append([f"{p['value']:g}", f"{p['total']:.3g}", fem] + _cells(p, names))
        lines.append(markdown(["value", "F total N", "FEM", *names], rows, "rrl"))
        lines.append("")
    path = out / "stability.md"
    atomic_write_text(path, "\n".join(lines))
    return path
