"""Learning curve: accuracy against the number of training placements, at a fixed step budget.

Trains a training config on seeded shares of its dataset's training placements
(``train_fraction``), each for the same number of optimiser steps (a smaller share gets more
epochs), then measures the validation and test splits (the same for every share). Prints a table
and writes it (markdown) and a log-log plot beside ``--out``. If the error still falls steeply at
the full share, more placements would pay; if it has flattened, the dataset is big enough for
this model.

Run: python benchmarks/learning_curve.py configs/train/uv_unet.yaml --steps 3000 \
         --fractions 0.125 0.25 0.5 1 --out runs/curve/uv_unet

A share's run resumes from ``<out>/f<share>/state.pt`` (a finished one is only measured again).
``--trained 1=runs/gnn_arm/gnn_arm.safetensors`` takes a share from a checkpoint trained
elsewhere (the zoo run), after checking that it was trained with the same config and steps.
Training times are the checkpoints' own (summed over resumed runs; ``-`` where a run predates
that record).
"""

from __future__ import annotations

import argparse
import json
import math
import pathlib

from stmpl.machine import describe
from stmpl.table import markdown


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("config", help="training config (YAML)")
    ap.add_argument("--fractions", type=float, nargs="+", default=[0.125, 0.25, 0.5, 1.0])
    ap.add_argument("--steps", type=int, default=3000, help="optimiser steps per share")
    ap.add_argument("--out", default=None, help="folder of the runs, table and plot")
    ap.add_argument("--data", help="dataset folder (default: the config's)")
    ap.add_argument(
        "--trained",
        nargs="+",
        default=[],
        metavar="SHARE=CHECKPOINT",
        help="shares already trained elsewhere with the same config and steps",
    )
    args = ap.parse_args()
    import torch

    from stmpl.data.dataset import Dataset
    from stmpl.pipeline.evaluate import evaluate_dataset
    from stmpl.pipeline.train import _split_tensors, read_config, train

    base = read_config(args.config)
    if args.data:
        base["data"] = args.data
    out = pathlib.Path(args.out or pathlib.Path("runs") / "curve" / base["name"])
    out.mkdir(parents=True, exist_ok=True)
    ds = Dataset(base["data"])
    n_places = ds.card["placements_per_split"]["train"]
    from stmpl import predictor

    trained = {}
    for item in args.trained:
        share, sep, path = item.partition("=")
        if not sep:
            raise SystemExit(f"--trained takes SHARE=CHECKPOINT, got {item!r}")
        trained[float(share)] = pathlib.Path(path)
    rows = []
    for frac in sorted(set(args.fractions) | set(trained)):
        cfg = {
            **base,
            "train_fraction": frac,
            "name": f"{base['name']}-f{frac:g}",
            "out": str(out / f"f{frac:g}"),
            "patience": 10**6,
        }
        n = len(_split_tensors(ds, "train", read_config(cfg), torch.device("cpu"))[0])
        cfg["epochs"] = max(1, math.ceil(args.steps / math.ceil(n / cfg["batch"])))
        if frac in trained:
            path = trained[frac]
            p = predictor.read(path)
            done = p.meta["training"]["epochs"]
            recipe = p.meta["training"].get("config", {})  # older checkpoints lack it
            same = {k: recipe.get(k) for k in ("batch", "lr", "schedule", "seed")}
            if (
                p.name != base["model"]
                or p.config != type(p).options(base["options"])
                or p.meta["dataset"]["hash"] != ds.card["hash"]
                or done != cfg["epochs"]
                or any(v is not None and v != base[k] for k, v in same.items())
            ):
                raise SystemExit(
                    f"{path} was not trained with {args.config}'s model, options "
                    f"and data for {cfg['epochs']} epochs (it has {done})"
                )
        else:
            path = train(cfg, progress=True)
            p = predictor.read(path)
        seconds = p.meta["training"]["seconds"]
        m = {s: evaluate_dataset(p, ds, s) for s in ("val", "test")}
        rows.append(
            {
                "fraction": frac,
                "placements": max(1, round(frac * n_places)),
                "samples": n,
                "epochs": cfg["epochs"],
                "seconds": round(seconds, 1),
                "checkpoint": str(path),
                **{f"{s}_{k}": m[s][k][0] for s in m for k in ("mee", "rel_mee")},
            }
        )
        print(json.dumps(rows[-1]), flush=True)
    lines = [
        f"Learning curve of `{args.config}` on {base['data']} (hash {ds.card['hash']}), "
        f"{args.steps} steps of batch {base['batch']} per share; {describe()}.",
        "",
    ]
    columns = ["share", "placements", "samples", "epochs", "train s", "val MEE mm"]
    columns += ["val rel. %", "test MEE mm", "test rel. %"]
    cells = []
    for r in rows:
        secs = f"{r['seconds']:.0f}" if r["seconds"] > 0 else "-"
        cells.append(
            [f"{r['fraction']:g}", r["placements"], r["samples"], r["epochs"], secs]
            + [f"{r['val_mee']:.4f}", f"{r['val_rel_mee']:.2f}"]
            + [f"{r['test_mee']:.4f}", f"{r['test_rel_mee']:.2f}"]
        )
    table = "\n".join(lines) + "\n" + markdown(columns, cells, "r" * 9)
    print(table)
    (out / "curve.md").write_text(table)
    (out / "curve.json").write_text(json.dumps(rows, indent=1))
    plot(rows, out / "curve.png", f"{base['name']}: {args.steps} steps per share")
    print(f"wrote {out / 'curve.md'} and {out / 'curve.png'}")


def plot(rows: list[dict], path, title: str) -> None:
    """Relative MEE (val and test) against training placements, log-log."""
    import matplotlib
    import numpy as np

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import FormatStrFormatter, NullFormatter

    fig, ax = plt.subplots(figsize=(5, 3.6))
    x = np.array([r["placements"] for r in rows])
    for s, style in (("val", "o--"), ("test", "s-")):
        ax.plot(x, [r[f"{s}_rel_mee"] for r in rows], style, label=f"{s} split")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xticks(x)
    for axis in (ax.xaxis, ax.yaxis):
        axis.set_major_formatter(FormatStrFormatter("%g"))
        axis.set_minor_formatter(NullFormatter())
    ax.set_yticks(
        np.round(
            np.geomspace(
                min(min(r["val_rel_mee"], r["test_rel_mee"]) for r in rows),
                max(max(r["val_rel_mee"], r["test_rel_mee"]) for r in rows),
                4,
            ),
            1,
        )
    )
    ax.set_xlabel("training placements")
    ax.set_ylabel("MEE / max displacement, %")
    ax.set_title(title)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


if __name__ == "__main__":
    main()
