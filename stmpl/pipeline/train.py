"""One training loop for every learned predictor (``stmpl train CONFIG``).

A config (YAML, checked on load) names the model kind and its options, the dataset folder (or a
list of folders of one part and FEM set-up, read as one: :class:`~stmpl.data.dataset.Datasets`), an
optional thickness filter (the paper's "seen levels" ablation), an optional share of the training
placements (``train_fraction``, for learning curves), optionally every training press twice on a
part that is its own mirror image (as solved and mirrored: ``mirror``,
:mod:`stmpl.pipeline.mirrored`), and the optimiser settings. The loop: Adam
(constant or cosine learning rate), shuffled mini-batches (seeded), validation loss every epoch,
early stopping with the best weights kept, a progress bar, CPU or CUDA. After every epoch the
full state goes to ``<out>/state.pt`` atomically, so a killed run resumes where it stopped. At
the end the best model is evaluated on the validation and test splits and written as a checkpoint
(``<out>/<name>.safetensors`` + sidecar) carrying its config, the dataset card's hash, and the
metrics. A model with a part computed from the dataset rather than learned (the linear FEM
operator) gets it from its ``fit(dataset)`` first; one with nothing to learn skips the optimiser.
"""

from __future__ import annotations

import json
import pathlib
import re
import time

import numpy as np
from tqdm import tqdm

from stmpl import config as checked
from stmpl import predictor
from stmpl.contact import gap as along
from stmpl.contact.posing import sample_way
from stmpl.data.dataset import open_data
from stmpl.files import atomic_path
from stmpl.pipeline import mirrored
from stmpl.pipeline.evaluate import evaluate_dataset
from stmpl.pipeline.selection import envelope, evidence, no_samples, selection

DEFAULTS = {
    "name": None,
    "model": None,
    "options": {},
    "data": None,
    "thickness_mm": None,
    "epochs": 100,
    "batch": 64,
    "lr": 1e-4,
    "schedule": "constant",
    "patience": 15,
    "seed": 0,
    "device": "cpu",
    "out": None,
    "max_train": None,
    "train_fraction": 1.0,
    "mirror": False,
}


SCHEDULES = ("constant", "cosine")
"""Learning-rate schedules: ``constant``, or ``cosine`` from ``lr`` down to 0 at the last step of
``epochs`` (stateless: the rate is a function of the step, so a resumed run follows it)."""


def learning_rate(cfg: dict, step: int, total: int) -> float:
    """The learning rate at optimiser step ``step`` of ``total``."""
    if cfg["schedule"] == "cosine":
        return 0.5 * cfg["lr"] * (1.0 + np.cos(np.pi * min(step, total) / total))
    return cfg["lr"]


DEVICE = re.compile(r"cpu|cuda(:[0-9]+)?|mps")


def read_config(source) -> dict:
    """A checked, completed training config from a YAML path or a dict."""
    cfg = checked.read(source, DEFAULTS, "training config", name="model")
    learned = [n for n in predictor.names() if n != "fem"]
    if cfg["model"] not in learned:
        raise ValueError(f"model must be a learned predictor {learned}, got {cfg['model']!r}")
    if not isinstance(cfg["options"], dict):
        raise ValueError(f"options must be a mapping of model options, got {cfg['options']!r}")
    predictor.get(cfg["model"]).options(cfg["options"])  # checked; kept as written
    data = cfg["data"]
    if not data or not (
        isinstance(data, str)
        or isinstance(data, list)
        and all(isinstance(d, str) and d for d in data)
    ):
        raise ValueError(
            f"data: the dataset folder (or list of folders) to train on is missing, got {data!r}"
        )
    if isinstance(data, list) and len(set(data)) < len(data):
        raise ValueError(f"data: a dataset folder is listed twice in {data}")
    for k in ("epochs", "batch", "patience"):
        checked.integer(cfg[k], k, 1)
    checked.integer(cfg["seed"], "seed", 0)
    if cfg["max_train"] is not None:
        checked.integer(cfg["max_train"], "max_train", 1)
    checked.number(cfg["lr"], "lr", 0, low_open=True)
    checked.number(cfg["train_fraction"], "train_fraction", 0, 1, low_open=True)
    checked.one_of(cfg["schedule"], "schedule", SCHEDULES)
    if not isinstance(cfg["mirror"], bool):
        raise ValueError(f"mirror must be true or false, got {cfg['mirror']!r}")
    if cfg["thickness_mm"] is not None and (
        not isinstance(cfg["thickness_mm"], list)
        or not all(checked.number(t, "thickness_mm", 0, low_open=True) for t in cfg["thickness_mm"])
    ):
        raise ValueError(
            f"thickness_mm must be a list of thicknesses in mm, got {cfg['thickness_mm']!r}"
        )
    if not isinstance(cfg["device"], str) or not DEVICE.fullmatch(cfg["device"]):
        raise ValueError(f"device must be cpu, cuda, cuda:N or mps, got {cfg['device']!r}")
    cfg["out"] = cfg["out"] or str(pathlib.Path("runs") / cfg["name"])
    return cfg


def _split_tensors(ds, split, cfg, device, p=None):
    """A split's ``thickness``, ``force``, ``displacement``, ``body`` (slot of each sample's
    body) and the prior's answers; for a model given a pose, the ``gap`` field
    (:func:`_pose_gaps`) in the place of the force and the contact ``pressure`` and ``push``
    beside the displacement. The prior's answers are in m; None unless the model has a prior
    and the data carry ``linear`` answers or span several bodies (then every sample's is at
    hand, the missing ones solved on its body once here).
    """
    import torch  # deferred: about a second to import; the core's types do not need it

    a, keep = selection(ds, split, cfg)
    if len(keep) == 0:
        raise no_samples(cfg, split)
    if getattr(p, "posed", False):  # the pose a model reads: along the press where it has one
        _require_poses(a, cfg)
        a = {**a, "gap": _pose_gaps(ds, a)}
        if p.motion:  # and the way the objects move there
            a["way"] = _pose_ways(ds, a, keep)
    if split == "train" and cfg.get("mirror", False):
        # every training press twice: as solved and mirrored
        a, keep = mirrored.with_mirrored(a, keep, mirrored.twin_of(ds))

    def t(x):
        return torch.tensor(np.asarray(x)[keep], dtype=torch.float32, device=device)

    body = (
        torch.tensor(a["body"][keep], dtype=torch.long, device=device)
        if len(ds.parts) > 1
        else None
    )  # one body: the model's own
    base = None
    if getattr(p, "prior", False) and ("linear" in a or len(ds.parts) > 1):
        base = _prior_answers(p, a, keep, torch.as_tensor(a["body"][keep], device=device), device)
    if getattr(p, "posed", False):  # given the pose: answers the displacement and the pressure
        target = np.concatenate(
            [a["displacement"], a["pressure"][..., None], a["push"][..., None]], -1
        )
        given = a["gap"] if "way" not in a else np.concatenate([a["gap"][..., None], a["way"]], -1)
        return t(a["thickness"]), t(given), t(target), body, base
    return t(a["thickness"]), t(a["force"]), t(a["displacement"]), body, base


def _pose_gaps(ds, a: dict) -> np.ndarray:
    """``(S, N)`` m: each sample's gap field as a pose model reads it
    (:func:`stmpl.contact.gap.of_sample`: along the press of a disk or a ball).
    """
    parts = getattr(ds, "parts", [ds.part])
    body = a["body"] if "body" in a else np.zeros(len(a["total"]), int)
    return np.stack(
        [
            along.of_sample(parts[b].vertices, k, params, g)
            for b, k, params, g in zip(body, a["kind"], a["params"], a["gap"])
        ]
    ).astype(np.float32)


def _pose_ways(ds, a: dict, keep) -> np.ndarray:
    """``(S, N, 3)`` m per m: each sample's way field (:func:`stmpl.contact.posing.sample_way`;
    zero for the samples not in ``keep``, which are not read), from the gap field ``a["gap"]``.
    """
    parts = getattr(ds, "parts", [ds.part])
    body = a["body"] if "body" in a else np.zeros(len(a["total"]), int)
    out = np.zeros((*np.shape(a["gap"]), 3), dtype=np.float32)
    for i in keep:
        out[i] = sample_way(parts[body[i]], a["kind"][i], a["params"][i], a["gap"][i])
    return out


def _require_poses(a: dict, cfg: dict) -> None:
    """Refuse a dataset without poses (arrays ``a``) for a model given a pose."""
    if any(k not in a for k in ("gap", "pressure", "push")):
        raise ValueError(
            f"a model given a pose learns from pressed objects: dataset {cfg['data']} has no "
            "gap, pressure and push arrays (make one with press_disk or press_sphere placements)"
        )


def _prior_answers(p, a, keep, body, device):
    """``(S, N, 3)`` m: the linear FEM's answer of every kept sample: the dataset's ``linear``
    where it has one, else solved on the sample's body (:meth:`LinearPrior.body_prior`).
    """
    import torch  # deferred: about a second to import; the core's types do not need it

    n = len(keep)
    out = torch.zeros(n, *a["displacement"].shape[1:], dtype=torch.float32, device=device)
    have = np.zeros(n, bool)
    if "linear" in a:
        lin = a["linear"][keep]
        have = np.isfinite(lin).all((1, 2))
        out[torch.as_tensor(have)] = torch.tensor(lin[have], dtype=torch.float32, device=device)
    todo = np.flatnonzero(~have)
    with torch.no_grad():
        for i in range(0, len(todo), 256):
            at = torch.as_tensor(todo[i : i + 256], device=device)
            th = torch.tensor(
                a["thickness"][keep][todo[i : i + 256]], dtype=torch.float32, device=device
            )
            f = torch.tensor(
                a["force"][keep][todo[i : i + 256]], dtype=torch.float32, device=device
            )
            b = body.index_select(0, at)
            for k in torch.unique(b).tolist():
                sel = torch.nonzero(b == k).flatten()
                out[at[sel]] = p.body_prior(k)(th[sel], f[sel])
    return out


def train(config, resume: bool = True, progress: bool = True):
    """Train the config's model; returns the path of the written checkpoint."""
    import torch  # deferred: about a second to import; the core's types do not need it

    cfg = read_config(config)
    out = pathlib.Path(cfg["out"])
    out.mkdir(parents=True, exist_ok=True)
    for stale in sorted(out.glob("*.tmp")):  # a run killed while it wrote
        stale.unlink()
        if progress:
            print(f"removed {stale}, left by a run that was killed while writing it")
    ds = open_data(cfg["data"])
    if progress and not ds.complete:
        print(
            f"{ds.folder} is a set part way ({ds.card['samples']} samples so far): the "
            "checkpoint's card says so"
        )
    p = _model(cfg, ds)
    device = torch.device(cfg["device"])
    t_fit = time.perf_counter()
    if hasattr(p, "fit"):  # a part computed from the dataset, not learned (a FEM operator)
        p.fit(ds, progress=progress)
    fitted = {"fit_seconds": round(time.perf_counter() - t_fit, 3)}
    if p.n_parameters() == 0:
        return _write_checkpoint(p, cfg, ds, out, [], float("nan"), fitted)
    opt = torch.optim.Adam(p.model.parameters(), lr=cfg["lr"])
    tr = _split_tensors(ds, "train", cfg, device, p)
    va = _split_tensors(ds, "val", cfg, device, p)
    state_path = out / "state.pt"
    run = {"epoch": 0, "best": np.inf, "best_state": None, "bad": 0, "history": []}
    if resume and state_path.exists():
        run = _resume(state_path, cfg, p, opt, device)
    gen = torch.Generator().manual_seed(cfg["seed"])
    for _ in range(run["epoch"]):  # the same shuffles as an uninterrupted run
        torch.randperm(len(tr[0]), generator=gen)
    bar = None
    if progress:
        bar = tqdm(
            total=cfg["epochs"],
            initial=run["epoch"],
            unit="epoch",
            desc=f"train {cfg['name']}",
            dynamic_ncols=True,
        )
    t0 = time.perf_counter()
    history = run["history"]
    before = history[-1].get("seconds", 0.0) if history else 0.0  # training time of earlier runs
    for epoch in range(run["epoch"], cfg["epochs"]):
        if run["bad"] >= cfg["patience"]:
            break
        loss = _epoch(p, opt, tr, cfg, epoch, gen, device)
        vloss = _validation_loss(p, va)
        history.append(
            {
                "epoch": epoch + 1,
                "train": loss,
                "val": vloss,
                "seconds": round(before + time.perf_counter() - t0, 3),
            }
        )
        if vloss < run["best"]:
            run["best"], run["bad"] = vloss, 0
            run["best_state"] = {k: v.detach().clone() for k, v in p.model.state_dict().items()}
        else:
            run["bad"] += 1
        run["epoch"] = epoch + 1
        _save_state(state_path, cfg, p, opt, run)
        if bar is not None:
            bar.update(1)
            bar.set_postfix(train=f"{loss:.3g}", val=f"{vloss:.3g}")
    if bar is not None:
        bar.close()
    p.model.load_state_dict(run["best_state"])
    return _write_checkpoint(p, cfg, ds, out, history, run["best"], fitted)


def _model(cfg: dict, ds):
    """The config's predictor, untrained, seeded, on the dataset's part with one slot per body
    and the envelope of its training scenes.
    """
    import torch  # deferred: about a second to import; the core's types do not need it

    if cfg["device"].startswith("cuda") and not torch.cuda.is_available():
        raise ValueError(f"device {cfg['device']} was asked for but CUDA is not available here")
    torch.manual_seed(cfg["seed"])
    np.random.seed(cfg["seed"])
    p = predictor.create(cfg["model"], ds.part, cfg["options"], device=cfg["device"])
    p.tissue = ds.card.get("tissue", "paper")  # its answers are judged by its data's tissue
    if len(ds.parts) > 1 and not p.general:
        raise ValueError(
            f"dataset {cfg['data']} spans {len(ds.parts)} bodies; a {cfg['model']} "
            "model of one body cannot learn them (give it the option geometry: "
            "true)"
        )
    for k, part in enumerate(ds.parts):
        if p.slot(part) != k:
            raise RuntimeError(f"body {k} of the dataset took another slot")
    p.envelope = envelope(ds, cfg)
    if getattr(p, "posed", False):  # how deep the training poses reach: beyond, outside
        a, keep = selection(ds, "train", cfg)
        _require_poses(a, cfg)
        p.meta["pose_deepest_mm"] = float(-1e3 * _pose_gaps(ds, a)[keep].min())
    return p


def _resume(state_path: pathlib.Path, cfg: dict, p, opt, device) -> dict:
    """The run saved in ``state_path`` (epoch, best loss and weights, epochs without progress,
    history), its model, optimiser and random state restored; refused when it belongs to
    another config (only ``epochs`` may change, to extend a run) or the file is broken.
    """
    import torch  # deferred: about a second to import; the core's types do not need it

    try:
        st = torch.load(state_path, map_location=device, weights_only=False)
    except Exception as e:  # noqa: BLE001 - torch raises many kinds for a broken file
        raise ValueError(
            f"{state_path} is truncated or corrupt ({type(e).__name__}); "
            "delete it or use --restart to train from the start"
        ) from e
    free = ("epochs", "out")  # a run may be extended, and its folder moved
    same = {k: v for k, v in st["config"].items() if k not in free}
    if same != {k: v for k, v in cfg.items() if k not in free}:
        raise ValueError(
            f"{state_path} belongs to another config (only epochs may change "
            "to extend a run); delete it, use --restart or another out folder"
        )
    p.model.load_state_dict(st["model"])
    opt.load_state_dict(st["opt"])
    torch.set_rng_state(st["rng"])
    return {k: st[k] for k in ("epoch", "best", "best_state", "bad", "history")}


def _save_state(state_path: pathlib.Path, cfg: dict, p, opt, run: dict) -> None:
    """Write the run so far atomically (a killed run resumes from its last epoch)."""
    import torch  # deferred: about a second to import; the core's types do not need it

    with atomic_path(state_path) as tmp:
        torch.save(
            {
                "config": cfg,
                "model": p.model.state_dict(),
                "opt": opt.state_dict(),
                **run,
                "rng": torch.get_rng_state(),
            },
            tmp,
        )


def _epoch(p, opt, tr: tuple, cfg: dict, epoch: int, gen, device) -> float:
    """One pass over the training split in shuffled batches, the learning rate set per step;
    returns the mean training loss.
    """
    import torch  # deferred: about a second to import; the core's types do not need it

    p.model.train()
    perm = torch.randperm(len(tr[0]), generator=gen).to(device)
    total = 0.0
    per_epoch = -(-len(perm) // cfg["batch"])
    for k, i in enumerate(range(0, len(perm), cfg["batch"])):
        idx = perm[i : i + cfg["batch"]]
        for g in opt.param_groups:
            g["lr"] = learning_rate(cfg, epoch * per_epoch + k, cfg["epochs"] * per_epoch)
        loss = p.loss(*(None if x is None else x[idx] for x in tr))
        opt.zero_grad()
        loss.backward()
        opt.step()
        total += float(loss.detach()) * len(idx)
    return total / len(perm)


def _validation_loss(p, va: tuple, batch: int = 256) -> float:
    """The mean loss over the validation split, in batches of ``batch``."""
    import torch  # deferred: about a second to import; the core's types do not need it

    p.model.eval()
    with torch.no_grad():
        return float(
            np.mean(
                [
                    float(p.loss(*(None if x is None else x[i : i + batch] for x in va)))
                    for i in range(0, len(va[0]), batch)
                ]
            )
        )


def _write_checkpoint(p, cfg, ds, out, history, best, extra) -> pathlib.Path:
    """Measure the final model on val (its envelope's evidence) and test and write its
    checkpoint and history.
    """
    extra = {**extra, "evidence": evidence(p, ds, cfg)}
    metrics = {
        s: evaluate_dataset(p, ds, s, thickness_mm=None)
        for s in ("val", "test")
        if ds.card["samples_per_split"][s]
    }
    folder = cfg["data"] if isinstance(cfg["data"], list) else str(cfg["data"])
    meta = {
        "dataset": {
            "folder": folder,
            "hash": ds.card["hash"],
            "name": ds.card["name"],
            "samples": ds.card["samples_per_split"],
            "tissue": ds.card.get("tissue", "paper"),
            "complete": ds.complete,
            **({"datasets": ds.card["datasets"]} if "datasets" in ds.card else {}),
        },
        "training": {
            "config": cfg,
            "epochs": len(history),
            "best_val": best if np.isfinite(best) else None,
            "seconds": history[-1].get("seconds", 0.0) if history else 0.0,
            "device": cfg["device"],
            **extra,
            "history": history[-5:],
        },
        "metrics": metrics,
    }
    path = p.save(out / f"{cfg['name']}.safetensors", meta)
    (out / "history.json").write_text(json.dumps(history))
    return path
