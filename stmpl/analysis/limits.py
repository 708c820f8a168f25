"""Caps on a predictor's envelope from a stability sweep: where the sweep
(:mod:`stmpl.analysis.stability`) measured a model breaking its per-scene promise
(:data:`stmpl.envelope.SCENE_PROMISE`) inside the support of its data, the cap on one load axis
that puts those points outside and keeps the most of the points where it held. ``stmpl zoo limit
--sweep CONFIG`` applies it to zoo models.
"""

from __future__ import annotations

import json
import pathlib

from stmpl.analysis.stability import read_config, scene_at
from stmpl.body.spec import part_from_spec
from stmpl.envelope import AXES, SLACK, _values, breaks_promise, features
from stmpl.files import atomic_write_text
from stmpl.pipeline import zoo


def broke(rec: dict, name: str) -> bool:
    """Whether predictor ``name`` broke its per-scene promise
    (:data:`stmpl.envelope.SCENE_PROMISE`) at point ``rec``: an answer where the FEM failed, a
    physically impossible answer, or one off by more than the promise. A refused scene was not
    answered and did not.
    """
    r = rec["predictors"].get(name, {})
    if "refused" in r or not r:
        return False
    if not rec["fem"]["ok"] or not r["physical"]:
        return True
    return breaks_promise(r["rel_mee"], r["peak_err"])


def measured(cfg: dict, part) -> list[tuple[object, list[dict]]]:
    """The sweep's points as ``(scene, records)``: every cached record of the scene (a cache
    may hold more than one, from earlier versions of the code; judge them together).
    """
    f = pathlib.Path(cfg["out"]) / "points.json"
    if not f.is_file():
        raise FileNotFoundError(f"{f} not found: run the stability sweep {cfg['name']} first")
    try:
        points = json.loads(f.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise ValueError(f"{f} is not the sweep's JSON ({e}); run the sweep again") from e
    if not isinstance(points, dict):
        raise ValueError(f"{f} must map points to records; run the sweep again")
    by = {}
    for key, rec in points.items():
        if isinstance(rec, dict) and "skipped" in rec:
            continue
        if (
            not isinstance(rec, dict)
            or any(k not in rec for k in ("axis", "value", "fem", "predictors"))
            or not isinstance(rec["fem"], dict)
            or "ok" not in rec["fem"]
            or not isinstance(rec["value"], (int, float))
        ):
            raise ValueError(f"{f}: point {key!r} is not a sweep record; run the sweep again")
        by.setdefault((rec["axis"], float(rec["value"])), []).append(rec)
    return [(scene_at(part, cfg["base"], a, v), recs) for (a, v), recs in sorted(by.items())]


LIMIT_AXES = ("contact_pressure", "peak_pressure", "contact_force", "contacts")
"""The axes a sweep may cap an envelope on (how hard, and how many places, the load presses)."""


def limit(cfg: dict, part, name: str, envelope, axes=LIMIT_AXES) -> dict | None:
    """The cap that keeps predictor ``name``'s envelope to its promise on the sweep: on each of
    ``axes``, the highest value among the points inside its envelope where it kept the promise,
    below the lowest one where it broke it (in any record), and far enough below that one that
    the envelope's slack does not reach it; of those, the cap that leaves the most kept points
    inside. Returns ``{"axis", "max" (SI), "kept", "broken", "lost"}`` (``lost``: kept points
    the cap puts outside), ``None`` when it broke its promise nowhere inside; ``ValueError``
    when no single cap separates them.
    """
    rows = []  # (feature values, broke?) of the points inside
    for scene, recs in measured(cfg, part):
        if not any(name in r["predictors"] for r in recs) or envelope.reasons(scene):
            continue
        rows.append(
            (features(part, scene.thickness, scene.force), any(broke(r, name) for r in recs))
        )
    if not any(b for _, b in rows):
        return None
    best = None
    for axis in axes:
        kept = [max(_values(f, axis)) for f, b in rows if not b and _values(f, axis)]
        broken = [max(_values(f, axis)) for f, b in rows if b and _values(f, axis)]
        below = [v for v in kept if v < min(broken)]
        if not below:
            continue
        cap = min(max(below), 0.999 * min(broken) / (1 + SLACK))
        lost = sum(v > cap * (1 + SLACK) for v in kept)
        if best is None or lost < best["lost"]:
            best = {
                "axis": axis,
                "max": cap,
                "kept": len(kept),
                "broken": len(broken),
                "lost": int(lost),
            }
    if best is None:
        raise ValueError(
            f"{name}: it breaks its promise at the lightest load the sweep measured "
            f"inside its envelope on every axis of {list(axes)}; no cap keeps it"
        )
    return best


def cap_zoo(names: list[str] | None, config, path=None, progress=print) -> dict:
    """Cap the envelopes of zoo models (default: the learned ones a stability sweep measured)
    where the sweep of ``config`` (its cached points; run it first) found them breaking
    :data:`stmpl.envelope.SCENE_PROMISE` inside their data's support (:func:`limit`: one cap, on
    the axis that keeps the most of the points where they held); the caps are kept in the
    manifest entries (``limits``) and applied by :func:`stmpl.pipeline.zoo.read`. Returns ``{name:
    cap or None}``.
    """
    cfg = read_config(config)
    part = part_from_spec(cfg["body"], cfg["part"])
    m = zoo.manifest(path)
    swept = [s[4:] for s in cfg["predictors"] if s.startswith("zoo:")]
    out = {}
    for name in names or swept:
        if name not in swept:
            raise ValueError(f"{name} is not among the sweep's predictors {swept}")
        e = m["models"][name]
        if e.get("kind") not in ("gnn", "uv_unet"):
            continue
        e.pop("limits", None)
        p = zoo.read(name, path=path)
        p.envelope.limits = {}  # its envelope without a cap
        lim = limit(cfg, part, name, p.envelope)
        out[name] = lim
        if lim is not None:
            e["limits"] = {
                lim["axis"]: {
                    "max": lim["max"],
                    "source": f"the stability sweep {cfg['name']}: kept at {lim['kept']} points, "
                    f"broke at {lim['broken']}",
                }
            }
        if progress:
            if lim is None:
                progress(f"{name}: keeps its promise inside its envelope at every point")
            else:
                kind, unit, k, what = AXES[lim["axis"]]
                progress(
                    f"{name}: {what} limited to {lim['max'] * k:.3g} {unit} (broke its "
                    f"promise at {lim['broken']} points inside; {lim['lost']} of the "
                    f"{lim['kept']} where it held now lie outside)"
                )
    atomic_write_text(zoo.root(path) / zoo.MANIFEST, json.dumps(m, indent=1, sort_keys=True))
    return out
