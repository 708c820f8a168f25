"""Which samples of a dataset a training config takes, and what they back: the envelope of its
training scenes and the evidence of a model measured on its validation scenes (never trained
on). Training writes both into a checkpoint; the zoo gives them to a model made before it did.
"""

from __future__ import annotations

import warnings

import numpy as np

from stmpl.data.format import at_levels
from stmpl.envelope import Envelope
from stmpl.failures import ImpossibleAnswer, OutsideEnvelope
from stmpl.metrics import sample_metrics
from stmpl.pipeline import mirrored
from stmpl.pipeline.evaluate import scenes_of
from stmpl.scene import Scene


def selection(ds, split: str, cfg: dict) -> tuple[dict, np.ndarray]:
    """``(arrays, indices)``: a split's arrays and the indices of its samples that a training
    config takes (its thickness levels; in training, its share of the placements, its cap on
    the samples, no place whose mirror twin is validated or tested).
    """
    a = ds.arrays(split)
    keep = np.arange(len(a["total"]))
    if cfg["thickness_mm"] is not None:
        keep = keep[at_levels(a, cfg["thickness_mm"])]
    if split == "train" and cfg["train_fraction"] < 1.0:  # a seeded share of the placements
        places = np.unique(a["placement"][keep])
        rng = np.random.default_rng(cfg["seed"])
        n = max(1, int(round(cfg["train_fraction"] * len(places))))
        chosen = rng.permutation(places)[:n]
        keep = keep[np.isin(a["placement"][keep], chosen)]
    if split == "train" and cfg["max_train"]:
        keep = keep[: int(cfg["max_train"])]
    if split == "train" and cfg.get("mirror", False):  # no place whose twin is validated or tested
        keep = mirrored.held_out(ds, a, keep, mirrored.twin_of(ds))
    return a, keep


def no_samples(cfg: dict, split: str) -> ValueError:
    """The error for a ``split`` that the config ``cfg`` leaves without samples."""
    which = {"train": "training", "val": "validation"}.get(split, split)
    kept = "" if cfg["thickness_mm"] is None else f" at thickness_mm {cfg['thickness_mm']}"
    return ValueError(f"dataset {cfg['data']} has no {which} samples{kept}")


def envelope(ds, cfg):
    """The :class:`~stmpl.envelope.Envelope` of the training scenes the config selects."""
    a, keep = selection(ds, "train", cfg)
    if len(keep) == 0:
        raise no_samples(cfg, "train")
    return Envelope.of(
        ds.parts,
        a["thickness"][keep],
        a["force"][keep],
        name="training",
        source=f"{ds.card['name']} ({ds.card['hash']}), train split",
        body=a["body"][keep],
    )


def evidence(p, ds, cfg) -> dict:
    """Measure predictor ``p`` on the validation scenes the config selects (never trained on)
    and add each to its envelope's support as evidence (:meth:`Envelope.measure`), the planned
    validation scenes the FEM could not solve too (no answer is backed there). Returns
    ``{"scenes": measured, "kept": of them the promise kept, "unsolved": added unsolved}``.
    """
    if p.envelope is None:
        return {}
    a, keep = selection(ds, "val", cfg)
    source = f"{ds.card['name']} ({ds.card['hash']}), validation split"
    rel, peak = [], []
    posed = None
    if getattr(p, "posed", False):
        motion = getattr(p, "motion", False)
        posed = scenes_of(ds, "val", cfg["thickness_mm"], given="pose", way=motion)[0]
    for i in range(0, len(keep), 64):
        at = keep[i : i + 64]
        if posed is not None:  # the same samples, given by their poses
            scenes = posed[i : i + 64]
        else:
            scenes = [
                Scene(
                    ds.parts[a["body"][k]],
                    a["thickness"][k].astype(float),
                    a["force"][k].astype(float),
                )
                for k in at
            ]
        with warnings.catch_warnings():  # measured, not warned
            warnings.simplefilter("ignore", OutsideEnvelope)
            warnings.simplefilter("ignore", ImpossibleAnswer)
            out = p.predict(scenes)
        for d, u in zip(out, a["displacement"][at]):
            m = sample_metrics(u.astype(float), d.displacement)
            rel.append(m["rel_mee"])
            peak.append(m["peak_err"])
    got = {"scenes": int(len(keep)), "kept": 0, "unsolved": 0}
    if len(keep):
        kept = p.envelope.measure(
            ds.parts, a["thickness"][keep], a["force"][keep], rel, peak, source, a["body"][keep]
        )
        got["kept"] = int(kept.sum())
    failed = ds.failed("val")
    if failed is not None:
        sel = np.arange(len(failed["total"]))
        if cfg["thickness_mm"] is not None:
            sel = sel[at_levels(failed, cfg["thickness_mm"])]
        if len(sel):
            nan = np.full(len(sel), np.nan)
            p.envelope.measure(
                ds.parts,
                failed["thickness"][sel],
                failed["force"][sel],
                nan,
                nan,
                source + ", not solved by the FEM",
                failed["body"][sel],
            )
            got["unsolved"] = int(len(sel))
    return got
