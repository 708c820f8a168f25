"""How honest the shipped models' answers are on scenes no model and no envelope was fitted on.

    stmpl generate configs/data/honesty_arm.yaml --out data/honesty_arm
    python benchmarks/honesty.py data/honesty_arm [--models gnn_arm_bodies ...]
        [--out reports/honesty]

Every planned scene of each set's test split is answered by each model: the scenes the FEM
solved are scored against it, the ones it could not solve (with its reason) are counted as
answered flagged (outside the envelope, physically impossible) or silent. Two counts decide:
the answers said inside the envelope that break the per-scene promise
(:data:`stmpl.envelope.SCENE_PROMISE`), and the answers on scenes the FEM could not solve that
said nothing. Writes ``honesty.md`` (and ``honesty.json``) under ``--out`` and prints the table.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from stmpl.data.dataset import open_data
from stmpl.envelope import SCENE_PROMISE
from stmpl.failures import PredictionFailed
from stmpl.machine import describe
from stmpl.metrics import honesty
from stmpl.pipeline import zoo
from stmpl.pipeline.evaluate import evaluate_dataset, on_unsolved

FINE_ARM = [
    "gnn_arm_bodies",
    "uv_unet_arm_bodies",
    "gnn_arm_fine",
    "uv_unet_arm_fine",
    "linear_arm_fine",
    "naive_arm_fine",
]
"""The shipped models of the once-subdivided left arm, which the honesty set is made on."""


def _totals(results: dict) -> dict:
    """Summed over every row: answers said inside and of them broken, and on scenes the FEM
    could not solve, answers flagged and silent.
    """
    inside = broken = flagged = silent = 0
    for s in results.values():
        share = s.get("inside_envelope", [np.nan])[0]
        if np.isfinite(share):
            inside += int(round(s["samples"] * share / 100))
        if np.isfinite(s.get("inside_broken", np.nan)):
            broken += int(s["inside_broken"])
        flagged += int(s.get("unsolved_flagged") or 0)
        silent += int(s.get("unsolved_silent") or 0)
    return {"inside": inside, "broken": broken, "flagged": flagged, "silent": silent}


def _at_level(model, ds, level: float) -> dict:
    """A model's answers on one thickness level of a set's test split; a level it refuses
    (a thickness its linear operator was not computed at) counts every planned scene there as
    flagged, none as inside.
    """
    solved = int(ds.card["samples_per_thickness_mm"].get(f"{level:g}", 0))
    try:
        if solved:
            return evaluate_dataset(model, ds, "test", thickness_mm=[level])
        return {"samples": 0, **on_unsolved(model, ds, "test", [level])}
    except (ValueError, PredictionFailed) as e:
        unsolved = on_unsolved(_Refusing(), ds, "test", [level])
        return {
            "samples": solved,
            "inside_envelope": [0.0, 0.0],
            "inside_broken": 0,
            **unsolved,
            "unsolved_flagged": unsolved["unsolved"],
            "unsolved_silent": 0,
            "refused": str(e).split("\n")[0],
        }


class _Refusing:
    """Stands for a model that refuses a level: :func:`on_unsolved` only counts its scenes."""

    batched = False


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("data", nargs="+", help="dataset folders (their test splits are used)")
    ap.add_argument("--models", nargs="+", default=FINE_ARM)
    ap.add_argument("--out", default="reports/honesty")
    args = ap.parse_args()
    sets = [open_data(d) for d in args.data]
    results, t0 = {}, time.perf_counter()
    for name in args.models:
        model = zoo.read(name)
        for folder, ds in zip(args.data, sets):
            for level in ds.card["config"]["thickness_mm"]:
                row = f"{name} at {level:g} mm"
                row = row if len(sets) == 1 else f"{row} / {Path(folder).name}"
                results[row] = _at_level(model, ds, float(level))
                print(f"{row}: {results[row].get('refused', 'answered')}", flush=True)
    totals = _totals(results)
    rel, peak = SCENE_PROMISE["rel_mee"], SCENE_PROMISE["peak_err"]
    promise = f"relative MEE <= {rel:g} %, peak within +-{peak:g} %"
    share = 100 * totals["broken"] / max(totals["inside"], 1)
    lines = [
        "# Honesty on scenes nothing was fitted on",
        "",
        f"Sets: {', '.join(args.data)} (test splits; every planned scene). Models: "
        f"{', '.join(args.models)}. Machine: {describe()}. "
        f"Command: `python benchmarks/honesty.py {' '.join(args.data)}` "
        f"({(time.perf_counter() - t0) / 60:.1f} min).",
        "",
        f"Per-scene promise: {promise}. Over every row: {totals['broken']} of "
        f"{totals['inside']} answers said inside broke it ({share:.1f} %); on the scenes the "
        f"FEM could not solve, {totals['flagged']} answers were flagged and "
        f"{totals['silent']} said nothing.",
        "",
        honesty(results),
        "",
        *[f"- {row}: refused ({r['refused']})" for row, r in results.items() if "refused" in r],
        "",
    ]
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "honesty.md").write_text("\n".join(lines))
    (out / "honesty.json").write_text(json.dumps({"totals": totals, "rows": results}, indent=1))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
