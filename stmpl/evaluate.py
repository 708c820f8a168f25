"""Evaluate predictors on a dataset split (``stmpl evaluate``): the paper's measures and ours
(:mod:`stmpl.metrics`), as a markdown table and a CSV file."""

from __future__ import annotations

import pathlib

import numpy as np


def scenes_of(ds, split: str, thickness_mm=None, limit: int | None = None):
    """``(scenes, true displacements (S, N, 3) m)`` of a dataset split."""
    from stmpl.scene import Scene

    a = ds.arrays(split)
    keep = np.arange(len(a["total"]))
    if thickness_mm is not None:
        lv = np.round(np.asarray(thickness_mm, float) * 1e-3, 6)
        keep = keep[np.isin(np.round(a["thickness"][:, 0], 6), lv)]
    if limit is not None:
        keep = keep[:limit]
    scenes = [Scene(ds.part, a["thickness"][i].astype(float), a["force"][i].astype(float),
                    meta={"placement": int(a["placement"][i]), "total": float(a["total"][i])})
              for i in keep]
    return scenes, a["displacement"][keep].astype(float)


def evaluate_dataset(predictor, ds, split: str = "test", thickness_mm=None,
                     limit: int | None = None, batch: int = 64) -> dict:
    """Summary (mean, std per measure; JSON-ready) of ``predictor`` on a dataset split."""
    from stmpl.metrics import sample_metrics, summarise

    scenes, truth = scenes_of(ds, split, thickness_mm, limit)
    if not scenes:
        raise ValueError(f"split {split!r} of {ds.folder} has no samples")
    rows, seconds = [], []
    for i in range(0, len(scenes), batch):
        out = predictor.predict(scenes[i:i + batch])
        for d, u in zip(out, truth[i:i + batch]):
            rows.append(sample_metrics(u, d.displacement))
            seconds.append(d.info.get("seconds", np.nan))
    s = summarise(rows)
    s["seconds_per_scene"] = (float(np.nanmean(seconds)), float(np.nanstd(seconds)))
    return {k: (list(v) if isinstance(v, tuple) else v) for k, v in s.items()}


def resolve(spec: str, device: str = "cpu"):
    """A predictor from a command-line spec: ``fem``, ``fem:medium``, ``zoo:<name>`` or a
    checkpoint path."""
    from stmpl import predictor, zoo

    if spec.startswith("zoo:"):
        return zoo.load(spec[4:], device=device)
    if spec == "fem" or spec.startswith("fem:"):
        return predictor.create("fem", res=spec.split(":", 1)[1] if ":" in spec else
                                "reference")
    path = pathlib.Path(spec)
    if path.suffix == ".safetensors" or path.exists():
        return predictor.load(path, device=device)
    raise ValueError(f"unknown predictor {spec!r}: give fem, fem:<resolution>, zoo:<name> or a "
                     ".safetensors checkpoint")


def evaluate(specs: list[str], data, split: str = "test", out=None, limit: int | None = None,
             device: str = "cpu") -> str:
    """Evaluate each predictor spec on ``data``'s split; returns the markdown table and, with
    ``out`` (a path without suffix or ending in .md), writes ``.md`` and ``.csv`` beside it."""
    from stmpl.data import Dataset
    from stmpl.metrics import table

    ds = Dataset(data)
    results = {}
    for spec in specs:
        s = evaluate_dataset(resolve(spec, device), ds, split, limit=limit)
        results[spec] = {k: tuple(v) if isinstance(v, list) else v for k, v in s.items()}
    md = table(results)
    if out is not None:
        out = pathlib.Path(out)
        base = out.with_suffix("") if out.suffix in (".md", ".csv") else out
        base.parent.mkdir(parents=True, exist_ok=True)
        base.with_suffix(".md").write_text(
            f"Dataset {ds.folder} ({ds.card['name']}, hash {ds.card['hash']}), split {split}\n\n"
            + md)
        base.with_suffix(".csv").write_text(table(results, "csv"))
    return md
