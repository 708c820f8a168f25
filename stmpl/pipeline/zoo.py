"""The model zoo: named, shipped checkpoints (``zoo/`` beside the package, or ``$STMPL_ZOO``).

``zoo/manifest.json`` lists each model: its name, file, SHA-256, size, the digest of its sidecar,
kind, config, the card of the dataset it learned from (name, hash, sample counts), its metrics
and how it was trained. A model is verified as a whole against the manifest before it is read:
the tensor file's size and SHA-256 and the sidecar's digest (so an edited displacement scale is
caught as surely as an altered tensor), then the sidecar against itself
(:mod:`stmpl.checkpoint`). A mismatch is refused with an error that names the file.

>>> from stmpl import zoo
>>> zoo.names()                       # doctest: +SKIP
['gnn_arm', 'linear_arm', 'naive_arm', 'uv_unet_arm']
>>> predictor = zoo.read("uv_unet_arm")  # doctest: +SKIP
"""

from __future__ import annotations

import json
import pathlib
import shutil
import warnings

import numpy as np

from stmpl import predictor
from stmpl.checkpoint import read as read_checkpoint
from stmpl.checkpoint import read_sidecar, sha256, sidecar_path
from stmpl.data.dataset import open_data
from stmpl.envelope import (
    PROMISE,
    SHAPE_AXES,
    Envelope,
    breaks_promise,
    features,
    scene_promise,
)
from stmpl.files import atomic_write_text
from stmpl.metrics import sample_metrics
from stmpl.pipeline.evaluate import evaluate_dataset, scenes_of
from stmpl.pipeline.manifest import (  # the manifest alone: read without torch
    FORMAT,
    MANIFEST,
    MAX_BYTES,
    check_name,
    entry,
    manifest,
    names,
    root,
)
from stmpl.pipeline.selection import envelope, evidence
from stmpl.predictor import OutsideEnvelope
from stmpl.support import Support, coordinates


def verify(name: str, path=None) -> pathlib.Path:
    """The checkpoint file of ``name`` after checking it as a whole against the manifest: the
    tensor file's size and SHA-256 and the sidecar's digest; raises ``ValueError`` naming the
    file that differs.
    """
    e = entry(name, path)
    f = root(path) / e["file"]
    if not f.is_file():
        raise FileNotFoundError(f"zoo model {name!r}: file {f} is missing")
    size = f.stat().st_size
    if size != e["bytes"]:
        raise ValueError(
            f"zoo model {name!r}: {f.name} is truncated or altered ({size} bytes, "
            f"the manifest says {e['bytes']})"
        )
    if sha256(f) != e["sha256"]:
        raise ValueError(
            f"zoo model {name!r}: {f.name} does not match the manifest's SHA-256 "
            "(tampered or corrupt)"
        )
    if "digest" not in e:
        raise ValueError(
            f"zoo model {name!r}: the manifest has no digest of its sidecar; add "
            "it again with `stmpl zoo add`"
        )
    side = read_sidecar(f)  # the sidecar against its own digest
    if side["digest"] != e["digest"] or side.get("sha256") != e["sha256"]:
        raise ValueError(
            f"zoo model {name!r}: {sidecar_path(f).name} does not match the "
            "manifest (an edited or replaced sidecar)"
        )
    return f


def read(name: str, device: str = "cpu", path=None, **options):
    """The predictor of zoo model ``name``, verified, on ``device``; its envelope gains the
    boxes of the test sets it kept its promise on (the manifest's ``envelope``). ``options``
    (e.g. ``fidelity``) go to its constructor.
    """
    p = predictor.read(verify(name, path), device=device, **options)
    e = entry(name, path)
    measured = e.get("envelope") or {}
    if p.envelope is not None and p.envelope.support is None and e.get("support"):
        p.envelope.support = Support.from_dict(e["support"]["support"])
    if p.envelope is not None:
        for k, v in measured.items():
            if v["kept"]:
                p.envelope.boxes[k] = v["box"]
                p.envelope.info[k] = v["info"]
            if p.envelope.support is not None and v.get("evidence", {}).get("coords"):
                ev = v["evidence"]
                errors = [[np.nan if x is None else x for x in r] for r in ev["errors"]]
                p.envelope.support.measure(
                    ev["coords"], ev["kept"], errors, f"{k}, test split", ev.get("promise")
                )
        for axis, lim in (e.get("limits") or {}).items():
            p.envelope.limit(axis, lim["max"], lim.get("source", ""))
    return p


def add(
    checkpoint,
    name: str,
    trained: dict | None = None,
    path=None,
    evaluate_on: list | None = None,
    replace: bool = False,
) -> dict:
    """Copy a checkpoint (and its sidecar) into the zoo as ``name`` and record it in the
    manifest with ``trained`` (how it was made: command, time, machine). ``evaluate_on``: more
    dataset folders (e.g. the out-of-distribution sets) whose test split is measured and kept in
    the entry's metrics under the dataset's name. A model of that name already there is
    replaced only with ``replace``. Returns the entry.
    """
    check_name(name)
    if not replace and (root(path) / MANIFEST).is_file() and name in names(path):
        raise ValueError(
            f"the zoo already has a model named {name!r}; choose another name or replace it "
            "(--force)"
        )
    src = pathlib.Path(checkpoint)
    _, meta = read_checkpoint(src)  # checks the file against its sidecar
    if meta["bytes"] > MAX_BYTES:
        raise ValueError(
            f"{src} is {meta['bytes'] / 2**20:.1f} MiB; the zoo takes at most "
            f"{MAX_BYTES / 2**20:.0f} MiB per model"
        )
    folder = root(path)
    folder.mkdir(parents=True, exist_ok=True)
    f = folder / MANIFEST
    m = manifest(path) if f.is_file() else {"format": FORMAT, "models": {}}
    dst = folder / f"{name}.safetensors"
    if src.resolve() != dst.resolve():
        shutil.copyfile(src, dst)
        shutil.copyfile(sidecar_path(src), sidecar_path(dst))
    e = {
        "file": dst.name,
        "sha256": meta["sha256"],
        "bytes": meta["bytes"],
        "digest": meta["digest"],
        "kind": meta["kind"],
        "part": meta.get("part"),
        "parameters": meta.get("parameters"),
        "config": meta.get("config"),
        "dataset": meta.get("dataset"),
        "metrics": meta.get("metrics"),
        "training": meta.get("training"),
        "trained": trained or {},
        "stmpl": meta.get("stmpl"),
    }
    if e["training"]:
        e["training"] = {k: v for k, v in e["training"].items() if k != "history"}
    if evaluate_on:
        _measure(predictor.read(dst), e, [open_data(d) for d in evaluate_on])
    m["models"][name] = e
    atomic_write_text(f, json.dumps(m, indent=1, sort_keys=True))
    return e


def measure(names: list[str] | None, datasets: list, path=None, progress=print) -> dict:
    """Measure zoo models (default all) on more datasets' test splits and keep the results in
    their manifest entries under each dataset's name (the files and the rest of the entries are
    untouched). Returns ``{name: {dataset: summary}}``.
    """
    if not datasets:
        raise ValueError("measure needs at least one dataset folder")
    sets = [open_data(d) for d in datasets]
    m = manifest(path)
    out: dict = {}
    for name in names or sorted(m["models"]):
        out[name] = _measure(predictor.read(verify(name, path)), m["models"][name], sets)
        for ds_name, res in out[name].items():
            if progress:
                progress(
                    f"{name} on {ds_name}: MEE {res['mee'][0]:.4f} mm, "
                    f"rel. {res['rel_mee'][0]:.2f} %, peak {res['peak_err'][0]:+.1f} "
                    f"+- {res['peak_err'][1]:.1f} %"
                )
    atomic_write_text(root(path) / MANIFEST, json.dumps(m, indent=1, sort_keys=True))
    return out


def support(names: list[str], data: list, path=None, progress=print) -> dict:
    """Give zoo models trained before envelopes carried a joint support one, from the datasets
    they were trained on (``data``: their folders, all of them): the support of the training
    split's scenes (:class:`~stmpl.support.Support`) and, as its first evidence, each model
    measured on the validation split (its unsolved planned scenes too), kept in the manifest
    entry beside the file (which stays as it is). The datasets must carry the names the model's
    card gives; a set made again (another hash) is accepted and both hashes are kept. Returns
    ``{name: {"training": training scenes, "scenes": validation scenes measured, "kept": of
    them the promise kept, "unsolved": unsolved validation scenes}}``.
    """
    if not names:
        raise ValueError("zoo support needs the names of the models to give a support")
    ds = open_data(data[0] if len(data) == 1 else data)
    given = [m.card["name"] for m in getattr(ds, "members", [ds])]
    m = manifest(path)
    out = {}
    for name in names:
        e = entry(name, path)
        card = e.get("dataset") or {}
        wanted = [d["name"] for d in card.get("datasets", [card])]
        if sorted(given) != sorted(wanted):
            raise ValueError(
                f"zoo model {name!r} was trained on {' + '.join(wanted)}; got {' + '.join(given)}"
            )
        p = predictor.read(verify(name, path))
        if p.envelope is None:
            raise ValueError(f"zoo model {name!r} has no envelope to give a support to")
        cfg = {
            "data": data,
            "thickness_mm": (e.get("config") or {}).get("thickness_mm"),
            "train_fraction": 1.0,
            "max_train": None,
        }
        trained = envelope(ds, cfg)
        p.envelope.support = trained.support
        got = {"training": trained.info["training"]["scenes"], **evidence(p, ds, cfg)}
        m["models"][name]["support"] = {
            "support": p.envelope.support.to_dict(),
            "dataset": ds.card["name"],
            "dataset_hash": ds.card["hash"],
            "trained_on_hash": card.get("hash"),
            "training_scenes": got["training"],
            "validation": {k: v for k, v in got.items() if k != "training"},
        }
        out[name] = got
        if progress:
            progress(
                f"{name}: support of {got['training']} training scenes of "
                f"{ds.card['name']} ({ds.card['hash']}); validation: {got.get('kept', 0)} of "
                f"{got.get('scenes', 0)} kept the per-scene promise, "
                f"{got.get('unsolved', 0)} unsolved"
            )
    atomic_write_text(root(path) / MANIFEST, json.dumps(m, indent=1, sort_keys=True))
    return out


def _measure(p, entry: dict, sets: list) -> dict:
    """Evaluate predictor ``p`` on each dataset's test split into ``entry["metrics"]`` under
    the dataset's name (with its hash); returns those results.
    """
    entry["metrics"] = dict(entry.get("metrics") or {})
    out = {}
    for ds in sets:
        out[ds.card["name"]] = {**evaluate_dataset(p, ds, "test"), "dataset_hash": ds.card["hash"]}
        box = _validate(p, ds)
        if box is not None:
            entry["envelope"] = {**(entry.get("envelope") or {}), ds.card["name"]: box}
    entry["metrics"].update(out)
    return out


def _validate(p, ds) -> dict | None:
    """The box by which dataset ``ds``'s test split widens ``p``'s training envelope (along the
    load's layout, :data:`~stmpl.envelope.SHAPE_AXES`, and for a set of several bodies along the
    body's size, ``skin_area``, from the scenes as intense as training ones), with the model's
    relative MEE and peak error on those scenes and whether they keep :data:`PROMISE`; ``None``
    if ``p`` has no training envelope or no scene qualifies.
    """
    if p.envelope is None or "training" not in p.envelope.boxes:
        return None
    scenes, truth = scenes_of(ds, "test")
    name = ds.card["name"]
    env = Envelope({"training": p.envelope.boxes["training"]})
    mask = env.widen(
        name,
        [s.part for s in scenes],
        np.stack([s.thickness for s in scenes]),
        np.stack([s.force for s in scenes]),
        source=f"{name} ({ds.card['hash']}), test split",
        body=np.arange(len(scenes)),
        axes=SHAPE_AXES + (("skin_area",) if len(getattr(ds, "parts", ())) > 1 else ()),
    )
    idx = np.flatnonzero(mask)
    if len(idx) == 0:
        return None
    rows = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", OutsideEnvelope)  # these scenes are the question
        for i in range(0, len(idx), 64):
            chunk = idx[i : i + 64]
            for k, d in zip(chunk, p.predict([scenes[k] for k in chunk])):
                rows.append(sample_metrics(truth[k], d.displacement))
    rel = float(np.nanmean([r["rel_mee"] for r in rows]))
    peak = np.array([r["peak_err"] for r in rows], dtype=float)
    peak = peak[np.isfinite(peak)]
    kept = rel <= PROMISE["rel_mee"] and abs(float(peak.mean())) <= PROMISE["peak_err"]
    return {
        "box": env.boxes[name],
        "info": env.info[name],
        "rel_mee": rel,
        "peak_err": [float(peak.mean()), float(peak.std())],
        "kept": bool(kept),
        "evidence": _evidence([scenes[k] for k in idx], rows, ds),
    }


def _evidence(scenes: list, rows: list, ds) -> dict:
    """Per scene of a measured test set (and per planned test scene the FEM could not solve):
    its coordinates (:func:`stmpl.support.coordinates`), whether the answer kept the per-scene
    promise and its relative MEE and peak error (%, ``None`` where unsolved): the evidence
    ``zoo.read`` adds to the model's support, so that the tails count, not the set's means.
    """
    coords, kept, errors = [], [], []
    for s, r in zip(scenes, rows):
        coords.append(coordinates(features(s.part, s.thickness, s.force)))
        ok = np.isfinite(r["rel_mee"]) and np.isfinite(r["peak_err"])
        kept.append(bool(ok and not breaks_promise(r["rel_mee"], r["peak_err"])))
        errors.append([float(r["rel_mee"]), float(r["peak_err"])] if ok else [None, None])
    failed = ds.failed("test") if hasattr(ds, "failed") else None
    parts = getattr(ds, "parts", [ds.part])
    if failed is not None:
        for t, f, b in zip(failed["thickness"], failed["force"], failed["body"]):
            coords.append(coordinates(features(parts[b], t.astype(float), f.astype(float))))
            kept.append(False)
            errors.append([None, None])
    return {
        "coords": np.round(np.array(coords), 5).tolist(),
        "kept": kept,
        "errors": errors,
        "promise": list(scene_promise()),
    }
