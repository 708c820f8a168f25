"""What a grip's answer owes to friction, and how much of it the linear FEM's closure finds from
the pose alone. On the layered forearm the fingers curl as they close and drag the skin under
them along; the rest of the limb follows the skin. Compared with the FEM on each split of the
grip set (relative MEE and peak error, the product's measures):

- the skin at rest, and the contact prior (the skin inside the hand moved out to its surface
  along the normal; what ``prior: contact`` starts from);
- the FEM's own displacement held within 1 cm of the hand, in full, and in its part normal to
  the skin alone (the skin free to slide): how much lies in the drag along the skin;
- the linear FEM's closure of the hand from first touch (:mod:`fem.closure`: stick and slip
  by Coulomb's law; what ``prior: closure`` starts from) without friction, at the set's
  friction coefficient (each step's contact the least-energy forces within Coulomb's disks, and
  by the rule of the models fitted before it, all at once: :data:`fem.closure.CONTACT_RULES`)
  and sticking
  throughout, and at the set's friction on the hand's own faces (no rounding), with its time a
  scene.

    python benchmarks/grip_closure.py [--data data/forearm_grips] [--splits test val train]

The compliance is :class:`fem.holding.SkinCompliance` (solved once per thickness and cached
in ``~/.cache/stmpl/holding``: the first run on a machine solves its columns, minutes).
"""

from __future__ import annotations

import argparse
import time

import numpy as np


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default="data/forearm_grips")
    ap.add_argument("--splits", nargs="+", default=["test", "val", "train"])
    args = ap.parse_args()

    from fem.holding import HeldSkin
    from fem.shapes import ROUNDING
    from stmpl.data.dataset import Dataset
    from stmpl.machine import describe
    from stmpl.metrics import sample_metrics
    from stmpl.pipeline.evaluate import scenes_of
    from stmpl.pose import within_reach

    ds = Dataset(args.data)
    cfg = ds.card["config"]
    mu = float(cfg.get("friction") or 0.0)
    skin = HeldSkin(ds.part, cfg["tissue"])
    normals = ds.part.normals
    print(describe())
    print(f"{args.data}: {ds.card['samples']} samples, friction {mu}, rounding {ROUNDING * 1e3} mm")
    rows = [
        ("rest", None),
        ("contact prior", None),
        ("FEM held within 1 cm", None),
        ("its normal part held", None),
        ("closure, no friction", (0.0, ROUNDING)),
        (f"closure, friction {mu:g}", (mu, ROUNDING)),
        (f"closure, friction {mu:g}, all at once", (mu, ROUNDING, "all_at_once")),
        ("closure, sticking", (np.inf, ROUNDING)),
        (f"closure, friction {mu:g}, faces unrounded", (mu, 0.0)),
    ]
    for split in args.splits:
        scenes, truth = scenes_of(ds, split, given="pose", way=True)
        got = {name: [] for name, _ in rows}
        seconds = []
        for s, u in zip(scenes, truth):
            gap, way, t = s.pose.gap, s.pose.way, s.thickness
            skin.hold(gap, t)  # the columns read in, so that the closure's time is its own
            answers = {
                "rest": np.zeros_like(u),
                "contact prior": normals * np.minimum(gap, 0.0)[:, None],
            }
            _, store = skin.store(t)
            band = np.flatnonzero((gap < 0.01) & within_reach(gap) & store.free)
            G = store.columns(band).astype(np.float64)
            at = (band[:, None] * 3 + np.arange(3)).ravel()
            f = np.linalg.solve(G[at], u[band].ravel())
            answers["FEM held within 1 cm"] = (G @ f).reshape(-1, 3)
            N = np.zeros((len(at), len(band)))
            N[np.arange(len(at)), np.repeat(np.arange(len(band)), 3)] = normals[band].ravel()
            fn = np.linalg.solve(N.T @ G[at] @ N, (u[band] * normals[band]).sum(1))
            answers["its normal part held"] = (G @ (N @ fn)).reshape(-1, 3)
            for name, kw in rows:
                if kw is None:
                    continue
                t0 = time.perf_counter()
                answers[name] = skin.closure(gap, way, t, *kw)
                if kw == (mu, ROUNDING):
                    seconds.append(time.perf_counter() - t0)
            peak = np.linalg.norm(u, axis=1).max()
            for name, d in answers.items():
                m = sample_metrics(u, d)
                got[name].append((m["rel_mee"], (np.linalg.norm(d, axis=1).max() / peak - 1) * 100))
        print(f"\n{split}: {len(scenes)} samples")
        print("| answer | relative MEE % | peak error % |")
        print("|---|--:|--:|")
        for name, r in got.items():
            r = np.array(r)
            print(
                f"| {name} | {r[:, 0].mean():.2f} ± {r[:, 0].std():.2f} "
                f"| {r[:, 1].mean():+.1f} ± {r[:, 1].std():.1f} |"
            )
        q = np.percentile(seconds, [25, 50, 75]) * 1e3
        print(
            f"closure at friction {mu:g}: {q[1]:.0f} ms a scene (quartiles {q[0]:.0f}-{q[2]:.0f})"
        )


if __name__ == "__main__":
    main()
