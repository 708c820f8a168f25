"""Accuracy measures: the paper's and ours.

The paper's (per sample, on the vertices whose true displacement exceeds 0.001 mm): MAE of x, y
and z, the mean Euclidean error (MEE), and the share of vertices with Euclidean error at most
0.1, 0.125, 0.15, 0.2 and 0.5 mm; reported as mean +- std over samples. Ours in addition: MEE
relative to the sample's maximum true displacement, the maximum error, the peak error (the
predicted largest displacement against the true one, signed %: a mean error can hide a peak that
is too deep or too shallow), the share of vertices with Euclidean error at most 1, 2 and 5 % of
the sample's largest true displacement (the millimetre thresholds saturate on shallow scenes and
say little on deep ones), and the seam gap of predictors that predict per UV corner (the spread
between a seam vertex's copies).

Inputs in metres, outputs in mm and %.
"""

from __future__ import annotations

import numpy as np

from stmpl.table import csv, markdown

ACTIVE_MM = 0.001
THRESHOLDS_MM = (0.1, 0.125, 0.15, 0.2, 0.5)
THRESHOLDS_PEAK = (1, 2, 5)
"""% of the sample's largest true displacement."""


def sample_metrics(true: np.ndarray, pred: np.ndarray, seam: np.ndarray | None = None) -> dict:
    """Measures of one sample. ``true``, ``pred``: ``(N, 3)`` displacements, m. With ``seam``
    (indices of the UV seam's vertices) also ``seam_mee``: the MEE over the active seam
    vertices, mm (NaN when none is active).
    """
    true, pred = np.asarray(true, float), np.asarray(pred, float)
    if true.shape != pred.shape or true.ndim != 2 or true.shape[1] != 3:
        raise ValueError(f"true and pred must both be (N, 3), got {true.shape} and {pred.shape}")
    if not (np.all(np.isfinite(true)) and np.all(np.isfinite(pred))):
        raise ValueError("displacements must be finite")
    mag = np.linalg.norm(true, axis=1) * 1e3
    active = mag > ACTIVE_MM
    out = {"active": int(active.sum()), "max_disp": float(mag.max())}
    if not active.any():
        return {
            **out,
            "mae_x": np.nan,
            "mae_y": np.nan,
            "mae_z": np.nan,
            "mee": np.nan,
            "rel_mee": np.nan,
            "max_err": np.nan,
            "peak_err": np.nan,
            **{f"ee<={t:g}": np.nan for t in THRESHOLDS_MM},
            **{f"ee<={t:g}%peak": np.nan for t in THRESHOLDS_PEAK},
            **({"seam_mee": np.nan} if seam is not None else {}),
        }
    err = (pred - true)[active] * 1e3
    ee = np.linalg.norm(err, axis=1)
    out.update(
        mae_x=float(np.abs(err[:, 0]).mean()),
        mae_y=float(np.abs(err[:, 1]).mean()),
        mae_z=float(np.abs(err[:, 2]).mean()),
        mee=float(ee.mean()),
        max_err=float(ee.max()),
    )
    out["rel_mee"] = 100.0 * out["mee"] / out["max_disp"]
    out["peak_err"] = 100.0 * (np.linalg.norm(pred, axis=1).max() * 1e3 / out["max_disp"] - 1.0)
    for t in THRESHOLDS_MM:
        out[f"ee<={t:g}"] = 100.0 * float((ee <= t).mean())
    for t in THRESHOLDS_PEAK:
        out[f"ee<={t:g}%peak"] = 100.0 * float((ee <= 0.01 * t * out["max_disp"]).mean())
    if seam is not None:
        on = np.zeros(len(true), bool)
        on[np.asarray(seam, int)] = True
        sel = on[active]
        out["seam_mee"] = float(ee[sel].mean()) if sel.any() else np.nan
    return out


def seam_gap(part, corner_displacement: np.ndarray) -> float:
    """Mean over seam vertices of the largest distance between their UV copies' predictions, mm.
    ``corner_displacement``: ``(T, 3)`` per UV corner (``part.uv`` order), m.
    """
    c = np.asarray(corner_displacement, float)
    if c.shape != (len(part.uv), 3):
        raise ValueError(f"corner displacement must be ({len(part.uv)}, 3), got {c.shape}")
    if not part.seam_groups:
        return 0.0
    gaps = []
    for g in part.seam_groups:
        p = c[g]
        gaps.append(np.linalg.norm(p[:, None] - p[None], axis=2).max())
    return 1e3 * float(np.mean(gaps))


def summarise(rows: list[dict]) -> dict:
    """Mean and std over samples of every measure: ``{"mee": (mean, std), ...}``, NaN-aware."""
    if not rows:
        raise ValueError("no samples to summarise")
    keys = [k for k in rows[0] if k != "active"]
    out = {}
    for k in keys:
        v = np.array([r[k] for r in rows], dtype=float)
        v = v[np.isfinite(v)]
        out[k] = (float(v.mean()), float(v.std())) if len(v) else (np.nan, np.nan)
    out["samples"] = len(rows)
    return out


def pooled(rows: list[dict]) -> dict:
    """One row of the evaluations ``rows`` (each as :func:`summarise` gives, with
    :data:`COUNTS`) over all their samples together: each measure's mean weighted by the rows'
    samples and its standard deviation over every sample (within the rows and between their
    means); the counts, samples and seconds summed, the reasons for unsolved scenes merged.
    """
    rows = [r for r in rows if r and r.get("samples")]
    if not rows:
        raise ValueError("no rows to pool")
    w = np.array([r["samples"] for r in rows], dtype=float)
    out: dict = {"samples": int(w.sum())}
    for k, v in rows[0].items():
        if isinstance(v, (list, tuple)) and len(v) == 2 and all(k in r for r in rows):
            m = np.array([r[k][0] for r in rows], dtype=float)
            sd = np.array([r[k][1] for r in rows], dtype=float)
            ok = np.isfinite(m) & np.isfinite(sd)
            if not ok.any():
                out[k] = (np.nan, np.nan)
                continue
            mean = float(np.sum(w[ok] * m[ok]) / w[ok].sum())
            var = np.sum(w[ok] * (sd[ok] ** 2 + (m[ok] - mean) ** 2)) / w[ok].sum()
            out[k] = (mean, float(np.sqrt(var)))
    for k in (*COUNTS, "evaluated_seconds"):
        if all(k in r for r in rows):
            out[k] = sum(r[k] for r in rows)
    why: dict = {}
    for r in rows:
        for reason, n in (r.get("unsolved_why") or {}).items():
            why[reason] = why.get(reason, 0) + n
    if why:
        out["unsolved_why"] = why
    return out


COLUMNS = (
    [
        ("mae_x", "MAE x"),
        ("mae_y", "MAE y"),
        ("mae_z", "MAE z"),
        ("mee", "MEE"),
        ("rel_mee", "MEE / max %"),
        ("max_err", "max err"),
        ("peak_err", "peak err %"),
    ]
    + [(f"ee<={t:g}", f"EE<={t:g} %") for t in THRESHOLDS_MM]
    + [(f"ee<={t:g}%peak", f"EE<={t:g} % of peak, %") for t in THRESHOLDS_PEAK]
    + [("seam_mee", "seam MEE"), ("seam_gap", "seam gap")]
)


REACTION = ("reaction_err", "reaction err %")
"""The column of the reaction's error against the FEM's, in a table where a row answers one (a
model given a pose: :func:`stmpl.pipeline.evaluate.evaluate_dataset`), after the peak's."""

DEPTH = ("depth_err", "depth err")
"""The column of how much deeper (mm) a model pressing to a force put the object than the FEM
did (:func:`stmpl.pipeline.evaluate.evaluate_to_force`), after the peak's."""


ANSWERED_BY_SOME = frozenset({REACTION[0], DEPTH[0], "seam_mee", "seam_gap"})
"""Columns only some rows answer (a reaction: a model given a pose, the FEM on pressed objects;
the UV seam's measures: a part with a seam): a table shows them where a row has them
(:func:`shown`)."""


def shown(cols, rows) -> list:
    """The columns ``cols`` (tuples whose first item is the key) that a table of the summaries
    ``rows`` shows: every one, except that one of :data:`ANSWERED_BY_SOME` only where a row has
    a finite value of it.
    """
    rows = list(rows)
    return [c for c in cols if c[0] not in ANSWERED_BY_SOME or any(_has(r, c[0]) for r in rows)]


def _has(row: dict, key: str) -> bool:
    """Whether a summary ``row`` holds a finite value (or mean) of ``key``."""
    v = row.get(key)
    v = v[0] if isinstance(v, (list, tuple)) else v
    try:
        return v is not None and bool(np.isfinite(float(v)))
    except (TypeError, ValueError):
        return False


def columns(results: dict[str, dict]) -> list:
    """:data:`COLUMNS`, with :data:`REACTION` and :data:`DEPTH` after the peak's error where a
    row has them.
    """
    at = [k for k, _ in COLUMNS].index("peak_err") + 1
    return shown([*COLUMNS[:at], REACTION, DEPTH, *COLUMNS[at:]], results.values())


COUNTS = ("unsolved", "unsolved_flagged", "unsolved_silent", "inside_broken")
"""Counts an evaluation adds (:func:`stmpl.pipeline.evaluate.evaluate_dataset`): the CSV's last
columns, empty where not known."""


def table(results: dict[str, dict], fmt: str = "markdown") -> str:
    """A table of summaries ``{predictor name: summarise(...)}`` as markdown or CSV."""
    cols = columns(results)
    if fmt == "csv":
        head = ["predictor", "samples"] + [f"{k}_{s}" for k, _ in cols for s in ("mean", "std")]
        head += list(COUNTS)
        rows = [
            [name, str(s["samples"])]
            + [f"{x:.6g}" for k, _ in cols for x in s.get(k, (np.nan, np.nan))]
            + ["" if s.get(k) is None else f"{s[k]:.6g}" for k in COUNTS]
            for name, s in results.items()
        ]
        return csv(head, rows)
    if fmt != "markdown":
        raise ValueError(f"fmt must be markdown or csv, got {fmt!r}")
    head = ["predictor", "n"] + [label + (" mm" if "%" not in label else "") for _, label in cols]
    rows = []
    for name, s in results.items():
        cells = [
            "–"
            if k not in s
            else f"{s[k][0]:.3f} ± {s[k][1]:.3f}"
            if "%" not in label
            else f"{s[k][0]:.1f} ± {s[k][1]:.1f}"
            for k, label in cols
        ]
        rows.append([name, str(s["samples"]), *cells])
    return markdown(head, rows, "lr" + "r" * len(cols))


def honesty(results: dict[str, dict]) -> str:
    """What each row's answers say about themselves, as markdown: the planned scenes, the ones
    the FEM did not solve when the set was made (with why) and how the predictor answered those
    (flagged: outside its envelope, impossible or refused; silent: as if trusted), the share of
    answers said inside its envelope, and how many of those break the per-scene promise
    (:data:`stmpl.envelope.SCENE_PROMISE`). ``results``: ``{row: evaluate_dataset(...)}``.
    """
    head = [
        "set-up",
        "planned",
        "solved",
        "not solved (why)",
        "flagged on those",
        "silent on those",
        "said inside %",
        "inside, promise broken",
    ]
    rows = []
    for name, s in results.items():
        n, un = int(s["samples"]) + int(s.get("failed", 0)), s.get("unsolved")  # FEM-solved
        why = ", ".join(f"{c} {r}" for r, c in sorted((s.get("unsolved_why") or {}).items()))
        inside = s.get("inside_envelope", (np.nan, np.nan))
        inside = inside[0] if isinstance(inside, (list, tuple)) else inside
        broken = s.get("inside_broken", np.nan)
        said_in = int(round(s["samples"] * inside / 100)) if np.isfinite(inside) else 0
        rows.append(
            [
                name,
                "–" if un is None else str(n + un),
                str(n),
                "not recorded" if un is None else f"{un}" + (f" ({why})" if why else ""),
                str(s.get("unsolved_flagged", "–")),
                str(s.get("unsolved_silent", "–")),
                "–" if not np.isfinite(inside) else f"{inside:.0f}",
                "–"
                if broken is None or not np.isfinite(broken)
                else f"{int(broken)}" + (f" of {said_in}" if said_in else ""),
            ]
        )
    return markdown(head, rows, "lrrlrrrr")
