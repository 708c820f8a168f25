"""Record shipped models' answers into ``tests/recorded/zoo_outputs.json`` as
``tests/pipeline/test_zoo.py`` checks them: a model added to the zoo, or one whose numbers a
change moves on purpose.

    python tests/recorded/record.py NAME [NAME ...]

A model given a force answers the test's scene on its own part (a 2 cm disk of 0.2 N on 7.5 mm
at chart point (0.42, 0.55)) at fidelity ``full`` and ``auto``; a model given an object's pose
answers the recorded grip (``data/forearm_grips``, test sample 2) with its reaction. Each is
answered with the skin's compliance and the linear prior's columns solved afresh (a cache
directory of its own), as the tests answer. A model recorded before keeps its vertices; a new
one takes those of the models of its kind (its deepest vertex and six spread over the part, for
the first of a part).
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import tempfile

import numpy as np

from stmpl import loads, tissue
from stmpl.body import AnnyBody
from stmpl.data.dataset import Dataset
from stmpl.pipeline import zoo
from stmpl.pipeline.evaluate import scenes_of
from stmpl.scene import Scene

RECORD = pathlib.Path(__file__).parent / "zoo_outputs.json"
ROOT = pathlib.Path(__file__).parents[2]
GRIP = {"data": "data/forearm_grips", "split": "test", "sample": 2}
"""The recorded grip of the pose models."""


def disk_scene(part) -> Scene:
    """The scene the models given a force answer: a 2 cm disk of 0.2 N on 7.5 mm of tissue at
    chart point (0.42, 0.55) of ``part``.
    """
    return Scene.from_load(
        part,
        tissue.constant(part, 0.0075),
        loads.disk(part, uv=(0.42, 0.55), radius=0.02, total=0.2),
    )


def _vertices(recorded: dict, name: str, kind: str, part: str, deepest: int, n: int) -> list:
    """The vertices to record: the entry's own, else those of a recorded model of the same kind
    (pose or force) and part, else the deepest and six spread over the part.
    """
    if name in recorded:
        return recorded[name]["vertices"]
    for r in recorded.values():
        if ("scene" in r) == (kind == "pose") and r["part"] == part:
            return r["vertices"]
    return sorted({0, deepest, *range(n // 7, n, n // 7)})


def record(name: str, recorded: dict) -> dict:
    """The entry of model ``name`` (a zoo name), answered afresh."""
    p = zoo.read(name)
    sub = int(p.part.source.get("subdivisions", 0))
    out = {"part": p.part.name, "subdivisions": sub}
    if "force" in p.takes:
        scene, kind = disk_scene(AnnyBody().part(p.part.name).subdivided(sub)), "force"
    else:
        scenes, _ = scenes_of(Dataset(ROOT / GRIP["data"]), GRIP["split"], given="pose", way=True)
        scene, kind = scenes[GRIP["sample"]], "pose"
        out["scene"] = GRIP
    d = p.predict(scene)
    u = d.displacement
    reach = np.linalg.norm(u, axis=1)
    v = _vertices(recorded, name, kind, p.part.name, int(reach.argmax()), len(u))
    out |= {
        "vertices": v,
        "displacement_m": u[v].tolist(),
        "sum_m": u.sum(0).tolist(),
        "deepest_m": float(reach.max()),
    }
    if kind == "pose":
        out["reaction_n"] = float(d.reaction)
    auto = p.with_fidelity("auto").predict(scene).displacement
    out["auto"] = {"displacement_m": auto[v].tolist(), "sum_m": auto.sum(0).tolist()}
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("names", nargs="+", help="zoo models to record")
    args = ap.parse_args()
    os.environ["STMPL_CACHE_DIR"] = tempfile.mkdtemp()  # columns solved afresh, as tests do
    recorded = json.loads(RECORD.read_text())
    for name in args.names:
        recorded[name] = record(name, recorded)
        print(f"{name}: deepest {1e3 * recorded[name]['deepest_m']:.4f} mm")
    RECORD.write_text(json.dumps(recorded, indent=1) + "\n")


if __name__ == "__main__":
    main()
