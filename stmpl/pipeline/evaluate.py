"""Evaluate predictors on a dataset split (``stmpl evaluate``): the paper's measures and ours
(:mod:`stmpl.metrics`), as a markdown table and a CSV file. A model given an object's pose is
measured at the sample's pose, or (``--to-force``, :func:`evaluate_to_force`) where the force is
what is known: each sample's object set where the FEM started pressing it
(:func:`stmpl.contact.posing.first_touch`) and pressed on by force control
(:func:`stmpl.contact.force_control.to_force`) until the model's own reaction meets the
sample's; its dent is then measured against the FEM's at that force, and how deep it put the
object against the FEM's depth.
"""

from __future__ import annotations

import pathlib
import time
import warnings
from collections import Counter

import numpy as np

from stmpl.contact import gap as along
from stmpl.contact.force_control import ForceNotMet, to_force
from stmpl.contact.posing import first_touch, sample_way
from stmpl.data.dataset import Dataset, Datasets, open_data
from stmpl.data.format import at_levels
from stmpl.envelope import breaks_promise
from stmpl.failures import ImpossibleAnswer
from stmpl.metrics import honesty, sample_metrics, seam_gap, summarise, table
from stmpl.pose import Pose
from stmpl.predictor import OutsideEnvelope, PredictionFailed, given_to
from stmpl.scene import Scene


def scenes_of(
    ds,
    split: str,
    thickness_mm=None,
    limit: int | None = None,
    given: str = "force",
    way: bool = False,
):
    """``(scenes, true displacements (S, N, 3) m)`` of a dataset split. ``given="pose"``: each
    scene given by its object's pose (its gap field, :func:`stmpl.contact.gap.of_sample`, and
    direction; a dataset of pressed objects), the sample's reaction (N) in ``meta["reaction"]``;
    with ``way`` its way field too (:func:`stmpl.contact.posing.sample_way`: a grip's hand is
    set again, or read from disk).
    """
    if limit is not None and (isinstance(limit, bool) or not isinstance(limit, int) or limit < 1):
        raise ValueError(f"limit must be a number of samples >= 1, got {limit!r}")
    a = ds.arrays(split)
    keep = np.arange(len(a["total"]))
    if thickness_mm is not None:
        keep = keep[at_levels(a, thickness_mm)]
    if limit is not None:
        keep = keep[:limit]
    parts = getattr(ds, "parts", [ds.part])
    body = a.get("body", np.zeros(len(a["total"]), int))
    if given == "pose":
        scenes = _posed_scenes(ds, a, keep, parts, body, way)
        return scenes, a["displacement"][keep].astype(float)
    scenes = [
        Scene(
            parts[body[i]],
            a["thickness"][i].astype(float),
            a["force"][i].astype(float),
            meta={"placement": int(a["placement"][i]), "total": float(a["total"][i])},
        )
        for i in keep
    ]
    return scenes, a["displacement"][keep].astype(float)


def _posed_scenes(ds, a: dict, keep, parts, body, way: bool = False) -> list[Scene]:
    """The samples ``keep`` of arrays ``a`` as scenes given by their object's pose (with
    ``way``, its way field too).
    """
    if "gap" not in a:
        raise ValueError(
            f"{ds.folder} holds no poses (gap field): it is not a dataset of pressed objects"
        )
    out = []
    for i in keep:
        params, part = a["params"][i], parts[body[i]]
        gap = along.of_sample(part.vertices, a["kind"][i], params, a["gap"][i])
        w = sample_way(part, a["kind"][i], params, gap) if way else None
        pose = Pose(gap, params["direction"], (), w)
        meta = {
            "placement": int(a["placement"][i]),
            "total": float(a["total"][i]),
            "reaction": float(params["reaction"]),
        }
        out.append(Scene.posed(part, a["thickness"][i].astype(float), pose, **meta))
    return out


def evaluate_dataset(
    predictor, ds, split: str = "test", thickness_mm=None, limit: int | None = None, batch: int = 64
) -> dict:
    """Summary (mean, std per measure; JSON-ready) of ``predictor`` on a dataset split;
    ``inside_envelope``: the share (%) of scenes inside the predictor's envelope (NaN without
    one).

    Seam measures: ``seam_mee`` (MEE on the UV seam's vertices) for every predictor, and
    ``seam_gap`` (how far a seam vertex's UV copies disagree, before they are averaged) for
    predictors that predict per UV corner (``corner_displacement``); a per-vertex predictor
    (GNN, Naive, FEM) gets 0: one value per vertex has no gap by construction.

    A predictor that is not ``batched`` (the FEM) answers one scene at a time; a scene it fails
    on is left out of the measures and counted (``failed``, the first reason in
    ``failed_first``).

    Honesty: ``inside_broken`` counts the answers said inside the envelope that break the
    per-scene promise (:data:`~stmpl.envelope.SCENE_PROMISE`; NaN without an envelope), and
    :func:`on_unsolved` adds the planned samples of the split the FEM did not solve when the
    set was made, and how the predictor answered them (flagged or silent).
    """
    import torch  # deferred: about a second to import; the core's types do not need it

    motion = getattr(predictor, "motion", False)
    scenes, truth = scenes_of(ds, split, thickness_mm, limit, given_to(predictor), motion)
    if not scenes:
        raise ValueError(f"split {split!r} of {ds.folder} has no samples")
    part = ds.part
    seam = part.seam_vertices
    predictor.load_kernels()  # many answers: the compiled loops pay
    rows, seconds, failed = [], [], []
    if not getattr(predictor, "batched", True):
        batch = 1  # the FEM: seconds a scene, and a solve may fail alone
    for i in range(0, len(scenes), batch):
        chunk = scenes[i : i + batch]
        with warnings.catch_warnings():  # measured, not warned: see inside_envelope
            warnings.simplefilter("ignore", OutsideEnvelope)
            try:
                out = predictor.predict(chunk)
            except PredictionFailed as e:  # counted and left out of the measures, with why
                if len(chunk) > 1:
                    raise
                failed.append(str(e))
                continue
        if hasattr(predictor, "corner_displacement"):
            t, f = (
                torch.tensor(np.asarray(x), dtype=torch.float32, device=predictor.device)
                for x in (np.stack([s.thickness for s in chunk]), predictor.given(chunk))
            )
            body = (
                predictor.bodies_of([s.part for s in chunk])
                if getattr(predictor, "general", False)
                else None
            )
            corners = predictor.corner_displacement(t, f, body)
        else:
            corners = [d.displacement[part.uv_vertex] for d in out]
        for d, u, c in zip(out, truth[i : i + batch], corners):
            m = sample_metrics(u, d.displacement, seam)
            if d.reaction is not None:  # a pose's answer: its reaction against the FEM's, %
                true = d.scene.meta["reaction"]
                m["reaction_err"] = 100.0 * (d.reaction - true) / true
            m["seam_gap"] = seam_gap(part, c)
            rows.append(_judged(m, d))
            seconds.append(d.info.get("seconds", np.nan))
    if not rows:
        raise PredictionFailed(
            f"{getattr(predictor, 'name', 'the predictor')} failed on all "
            f"{len(scenes)} scenes of {ds.folder} ({split}): {failed[0]}"
        )
    return _summary(rows, seconds, failed, on_unsolved(predictor, ds, split, thickness_mm, batch))


def _judged(m: dict, d) -> dict:
    """A sample's measures ``m`` with what the answer ``d`` said of itself: ``inside_envelope``
    (100 or 0; NaN without an envelope) and ``broken``, whether it said inside yet breaks the
    per-scene promise (:func:`~stmpl.envelope.breaks_promise`; NaN without an envelope).
    """
    env = d.info.get("envelope")
    if env is None:
        return {**m, "inside_envelope": np.nan, "broken": np.nan}
    broken = bool(env["inside"]) and bool(np.isfinite(m["rel_mee"]))
    broken = broken and bool(breaks_promise(m["rel_mee"], m["peak_err"]))
    return {**m, "inside_envelope": 100.0 * env["inside"], "broken": float(broken)}


def _summary(rows: list[dict], seconds: list, failed: list[str], unsolved: dict) -> dict:
    """The JSON-ready summary of judged samples ``rows`` (:func:`_judged`): each measure's mean
    and spread, the seconds a scene, the answers that failed (counted, the first reason kept),
    how many said inside broke the promise (NaN without an envelope) and ``unsolved``
    (:func:`on_unsolved`).
    """
    broken = np.array([r.pop("broken") for r in rows], dtype=float)
    s = summarise(rows)
    s["seconds_per_scene"] = (float(np.nanmean(seconds)), float(np.nanstd(seconds)))
    if failed:
        s["failed"], s["failed_first"] = len(failed), failed[0]
    s["inside_broken"] = int(np.nansum(broken)) if np.isfinite(broken).any() else float("nan")
    s.update(unsolved)
    return {k: (list(v) if isinstance(v, tuple) else v) for k, v in s.items()}


def on_unsolved(predictor, ds, split: str = "test", thickness_mm=None, batch: int = 64) -> dict:
    """The planned samples of a split that the FEM did not solve when the set was made (a failed
    solve, or a load past the set's ``max_pressure``), counted and never dropped: ``unsolved``
    (``None`` for a set made before failures kept their inputs), ``unsolved_why`` (count per
    reason) and the predictor's answers on them: ``unsolved_flagged`` (outside its envelope,
    physically impossible, or refused) and ``unsolved_silent`` (answered as if trusted). A
    predictor that is not ``batched`` (the FEM) is not asked again.
    """
    got = ds.failed(split) if hasattr(ds, "failed") else None
    if got is None:
        return {"unsolved": None}
    keep = np.arange(len(got["total"]))
    if thickness_mm is not None:
        keep = keep[at_levels(got, thickness_mm)]
    out = {
        "unsolved": int(len(keep)),
        "unsolved_why": dict(Counter(got["reason"][i].split(":")[0] for i in keep)),
    }
    if not getattr(predictor, "batched", True) or len(keep) == 0:
        return out
    if given_to(predictor) == "pose":
        return out  # a failed press keeps no pose to ask a pose model about: counted only
    parts = getattr(ds, "parts", [ds.part])
    scenes = [
        Scene(
            parts[got["body"][i]],
            got["thickness"][i].astype(float),
            got["force"][i].astype(float),
            meta={"total": float(got["total"][i]), "unsolved": got["reason"][i]},
        )
        for i in keep
    ]
    flagged = silent = 0
    for i in range(0, len(scenes), batch):
        chunk = scenes[i : i + batch]
        with warnings.catch_warnings():  # counted, not warned
            warnings.simplefilter("ignore", OutsideEnvelope)
            warnings.simplefilter("ignore", ImpossibleAnswer)
            try:
                answers = predictor.predict(chunk)
            except PredictionFailed:  # refused (a strict predictor): flagged, not silent
                flagged += len(chunk)
                continue
        for d in answers:
            env = d.info.get("envelope")
            if (env is not None and not env["inside"]) or not d.info.get("physical", True):
                flagged += 1
            else:
                silent += 1
    return {**out, "unsolved_flagged": flagged, "unsolved_silent": silent}


def evaluate_to_force(
    predictor, ds, split: str = "test", thickness_mm=None, limit: int | None = None
) -> dict:
    """Summary (mean, std per measure; JSON-ready) of a pose model ``predictor`` on a dataset
    of pressed objects, each sample's force met by force control from the object's first touch.
    Beside the measures of :func:`stmpl.pipeline.evaluate.evaluate_dataset`: ``depth_err``,
    how much deeper (mm) the model put the object than the FEM did for the same force (its
    deepest skin vertex inside the object at rest), and ``answers``, how many answers each
    search took. A force the model's answers never meet is counted in ``failed`` with the
    first reason in ``failed_first``, never dropped; ``seconds_per_scene`` is the whole search's.
    """
    if given_to(predictor) != "pose":
        raise ValueError(
            f"{predictor.name} takes a force: --to-force measures models given an object's pose"
        )
    scenes, truth = scenes_of(ds, split, thickness_mm, limit, "pose")
    if not scenes:
        raise ValueError(f"split {split!r} of {ds.folder} has no samples")
    a = ds.arrays(split)
    keep = np.arange(len(a["total"]))
    if thickness_mm is not None:
        keep = keep[at_levels(a, thickness_mm)]
    keep = keep[: len(scenes)]
    rows, seconds, failed = [], [], []
    for s, u, i in zip(scenes, truth, keep):
        start = first_touch(s.part, s.thickness, a["kind"][i], a["params"][i])
        t0 = time.perf_counter()
        with warnings.catch_warnings():  # measured, not warned: see inside_envelope
            warnings.simplefilter("ignore", OutsideEnvelope)
            try:
                d = to_force(predictor, start, s.meta["reaction"])
            except (ForceNotMet, PredictionFailed) as e:
                failed.append(str(e))
                continue
        seconds.append(time.perf_counter() - t0)
        m = sample_metrics(u, d.displacement)
        m["depth_err"] = 1e3 * (d.scene.pose.depth - s.pose.depth)
        m["answers"] = d.info["force_control"]["answers"] or np.nan  # the FEM's: its own
        rows.append(_judged(m, d))
    if not rows:
        raise PredictionFailed(
            f"{predictor.name} met the force of none of the {len(scenes)} samples of "
            f"{ds.folder} ({split}): {failed[0]}"
        )
    return _summary(rows, seconds, failed, on_unsolved(predictor, ds, split, thickness_mm))


def evaluate(
    predictors: dict,
    data,
    split: str = "test",
    out=None,
    limit: int | None = None,
    to_force: bool = False,
) -> str:
    """Evaluate each predictor (``{label: predictor}``) on ``data``'s split (a dataset folder or
    a :class:`~stmpl.data.dataset.Dataset`); returns the markdown table and, with ``out`` (a path
    without suffix or ending in .md), writes ``.md`` and ``.csv`` beside it. ``to_force``: pose
    models given each sample's force instead of its pose
    (:func:`evaluate_to_force`).
    """
    ds = data if isinstance(data, (Dataset, Datasets)) else open_data(data)
    results = {}
    for name, p in predictors.items():
        if to_force:
            s = evaluate_to_force(p, ds, split, limit=limit)
        else:
            s = evaluate_dataset(p, ds, split, limit=limit)
        results[name] = {k: tuple(v) if isinstance(v, list) else v for k, v in s.items()}
    md = table(results) + "\nWhat the answers say about themselves:\n\n" + honesty(results)
    if not ds.complete:
        md += f"\nThe dataset is a set part way: {len(ds)} samples so far.\n"
    for name, s in results.items():
        if s.get("failed"):
            md += (
                f"\n{name}: {s['failed']} of {s['samples'] + s['failed']} samples not answered "
                f"(first: {s['failed_first']})\n"
            )
    if out is not None:
        out = pathlib.Path(out)
        base = out.with_suffix("") if out.suffix in (".md", ".csv") else out
        base.parent.mkdir(parents=True, exist_ok=True)
        base.with_suffix(".md").write_text(
            f"Dataset {ds.folder} ({ds.card['name']}, hash {ds.card['hash']}), split {split}\n\n"
            + md
        )
        base.with_suffix(".csv").write_text(table(results, "csv"))
    return md
