"""A drag over the whole arm with nothing solved yet: how long each press waits, with a
stand-in (:class:`stmpl.responsive.Responsive`) and without.

    python benchmarks/first_touch.py [--seconds 20] [--rate 100] [--places 120]
        [--model gnn_arm_bodies] [--stand-in naive_arm_fine] [--plain 4] [--prepare]

An empty column cache (a temporary ``STMPL_CACHE_DIR``); the model at fidelity ``auto`` on the
once-subdivided left arm; a 1.5 cm disk of 0.3 N on 7.5 mm dragged along the arm's chart (u from
0.15 to 0.9 at v = 0.5, then back at v = 0.55; ``--places`` places, built before the clock starts)
at ``--rate`` presses a second for ``--seconds``. With the stand-in every press is answered by
the model where its linear prior's columns are solved and by the stand-in (marked) while they
are solved in the background. Printed: the latency per press (median, 95th percentile, largest),
the share the stand-in answered, and how many places the model answered itself; then the model
alone on its first ``--plain`` new places, each waiting for its columns. ``--prepare``: then, in
another empty cache, the model prepares the arm ahead (``Predictor.prepare``: every column it
can need, timed) and the same drag is pressed on it alone. Run it alone: the times are
wall-clock.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
import warnings

import numpy as np


def places(arm, n: int) -> list:
    """``n`` scenes along the chart: there and back, a 1.5 cm disk of 0.3 N on 7.5 mm."""
    from stmpl import Scene, loads, tissue

    thick = tissue.constant(arm, 0.0075)
    half = n // 2
    uv = [(u, 0.5) for u in np.linspace(0.15, 0.9, half)]
    uv += [(u, 0.55) for u in np.linspace(0.9, 0.15, n - half)]
    out = []
    for p in uv:
        try:
            out.append(Scene.from_load(arm, thick, loads.disk(arm, uv=p, radius=0.015, total=0.3)))
        except ValueError:  # off the chart
            continue
    return out


def drag(live, scenes: list, seconds: float, rate: float) -> tuple[np.ndarray, np.ndarray]:
    """Press ``scenes`` in order over ``seconds`` at ``rate`` presses a second; per press its
    latency (s) and whether the stand-in answered.
    """
    total = int(seconds * rate)
    waits, stood = np.zeros(total), np.zeros(total, bool)
    start = time.perf_counter()
    for i in range(total):
        due = start + i / rate
        now = time.perf_counter()
        if now < due:
            time.sleep(due - now)
        scene = scenes[min(len(scenes) - 1, i * len(scenes) // total)]
        t0 = time.perf_counter()
        d = live.predict(scene)
        waits[i] = time.perf_counter() - t0
        stood[i] = "stand_in" in d.info
    return waits, stood


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=20.0)
    ap.add_argument("--rate", type=float, default=100.0)
    ap.add_argument("--places", type=int, default=120)
    ap.add_argument("--model", default="gnn_arm_bodies")
    ap.add_argument("--stand-in", default="naive_arm_fine")
    ap.add_argument("--plain", type=int, default=4)
    ap.add_argument("--prepare", action="store_true", help="then prepare the arm ahead, and drag")
    args = ap.parse_args(argv)
    os.environ["STMPL_CACHE_DIR"] = tempfile.mkdtemp(prefix="stmpl-first-touch-")

    from stmpl import AnnyBody
    from stmpl.machine import describe
    from stmpl.pipeline import zoo
    from stmpl.predictor import ImpossibleAnswer, OutsideEnvelope
    from stmpl.responsive import Responsive

    warnings.simplefilter("ignore", OutsideEnvelope)
    warnings.simplefilter("ignore", ImpossibleAnswer)
    arm = AnnyBody().part("left_arm").subdivided(1)
    scenes = places(arm, args.places)
    model = zoo.read(args.model, fidelity="auto")
    stand_in = zoo.read(args.stand_in)
    for s in scenes[:2]:
        stand_in.predict(s)  # warm: the stand-in's first call
    print(f"{describe()}; left arm, {arm.n_vertices} vertices; {len(scenes)} places")
    print(f"{args.model} (auto) with {args.stand_in} standing in; empty column cache\n")

    live = Responsive(model, stand_in)
    waits, stood = drag(live, scenes, args.seconds, args.rate)
    ms = 1e3 * waits
    own = sum(1 for s in scenes if not model.missing(s))
    print(
        f"drag, {len(ms)} presses at {args.rate:g}/s: median {np.median(ms):.2f} ms, "
        f"p95 {np.percentile(ms, 95):.2f} ms, largest {ms.max():.1f} ms (press "
        f"{int(ms.argmax()) + 1}); the stand-in answered "
        f"{100 * stood.mean():.0f} % of them; the model had solved {own} of {len(scenes)} places "
        f"by the end"
    )
    if live.errors:
        print("preparation errors: " + "; ".join(live.errors[:3]))
    live.wait()

    os.environ["STMPL_CACHE_DIR"] = tempfile.mkdtemp(prefix="stmpl-first-touch-")
    plain = zoo.read(args.model, fidelity="auto")
    far = scenes[:: max(1, len(scenes) // max(1, args.plain))][: args.plain]
    alone = []
    for s in far:
        t0 = time.perf_counter()
        plain.predict(s)
        alone.append(time.perf_counter() - t0)
    print(
        f"the model alone at {len(far)} new places: "
        + ", ".join(f"{t:.1f} s" for t in alone)
        + " before each answer"
    )
    if not args.prepare:
        return
    os.environ["STMPL_CACHE_DIR"] = tempfile.mkdtemp(prefix="stmpl-first-touch-")
    prepared = zoo.read(args.model, fidelity="auto")
    t0 = time.perf_counter()
    solved = prepared.prepare(arm, scenes[0].thickness)
    print(f"prepared ahead: {solved} columns in {time.perf_counter() - t0:.0f} s")
    waits, _ = drag(prepared, scenes, args.seconds, args.rate)
    ms = 1e3 * waits
    print(
        f"drag on the prepared model alone, {len(ms)} presses: median {np.median(ms):.2f} ms, "
        f"p95 {np.percentile(ms, 95):.2f} ms, largest {ms.max():.1f} ms"
    )


if __name__ == "__main__":
    main()
