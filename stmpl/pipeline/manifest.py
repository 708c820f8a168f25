"""The zoo's manifest and what reads only it: the folder, the checked manifest, its entries,
and the tables ``stmpl zoo list`` and ``show`` print. No model is read here (nor torch
imported), so listing the zoo is instant; :mod:`stmpl.pipeline.zoo` verifies, reads and
extends it.
"""

from __future__ import annotations

import copy
import functools
import json
import os
import pathlib
import re

from stmpl.table import markdown

MANIFEST = "manifest.json"
FORMAT = "stmpl-zoo/1"
MAX_BYTES = 10 * 2**20
"""The largest checkpoint the zoo accepts (10 MiB): the repository ships its models."""
NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.-]{0,63}")
"""A model name: letters, digits, ``_``, ``.``, ``-``; no path (it names files in the zoo)."""


def check_name(name: str) -> str:
    """``name`` if it is a valid model name (:data:`NAME`, not ``..``-like); else ``ValueError``."""
    if not isinstance(name, str) or not NAME.fullmatch(name) or ".." in name:
        raise ValueError(
            f"zoo model name {name!r} is not allowed: use letters, digits, _, . and "
            "- (it names files inside the zoo folder, so no paths)"
        )
    return name


def root(path=None) -> pathlib.Path:
    """The zoo folder: ``path``, else ``$STMPL_ZOO``, else ``zoo/`` beside the package."""
    if path is not None:
        return pathlib.Path(path)
    if os.environ.get("STMPL_ZOO"):
        return pathlib.Path(os.environ["STMPL_ZOO"])
    return pathlib.Path(__file__).resolve().parents[2] / "zoo"


def manifest(path=None) -> dict:
    """The zoo's manifest (``{"format", "models": {name: entry}}``), checked."""
    folder = root(path)
    f = folder / MANIFEST
    if not f.is_file():
        raise FileNotFoundError(
            f"no model zoo at {folder} ({MANIFEST} is missing); set STMPL_ZOO or pass the folder"
        )
    try:
        m = json.loads(f.read_text())
    except json.JSONDecodeError as e:
        raise ValueError(f"zoo manifest {f} is corrupt: {e}") from e
    if m.get("format") != FORMAT or not isinstance(m.get("models"), dict):
        raise ValueError(f"{f} is not a stmpl zoo manifest (format {m.get('format')!r})")
    return m


def names(path=None) -> list[str]:
    """Names of the zoo's models."""
    return sorted(manifest(path)["models"])


def entry(name: str, path=None) -> dict:
    """The manifest entry of model ``name`` (a copy: the manifest is read once per process
    and version of the file, some megabytes of envelope evidence).
    """
    f = root(path) / MANIFEST
    if not f.is_file():
        manifest(path)  # says which folder has no manifest
    stat = f.stat()
    models = _read(str(f), stat.st_mtime_ns, stat.st_size)["models"]
    if name not in models:
        raise KeyError(f"no model {name!r} in the zoo at {root(path)}; it has {sorted(models)}")
    return copy.deepcopy(models[name])


@functools.lru_cache(maxsize=4)
def _read(file: str, mtime_ns: int, size: int) -> dict:
    """:func:`manifest` of the zoo folder of ``file``, kept for this version of the file."""
    return manifest(pathlib.Path(file).parent)


LABELS = {
    "test": "in-distribution test",
    "bodies": "seen bodies",
    "bodies_test": "unseen bodies",
    "bodies_bands": "unseen bodies: bands",
    "bodies_letters": "unseen bodies: letters",
    "bodies_grasps": "unseen bodies: grasps",
    "bodies_palms": "unseen bodies: palms",
}
"""Column titles of the sets whose names do not say it (the test splits of the training bodies,
``bodies_fine``, and of the held-out ones), in the table's order; other sets follow by name."""


def _column(key: str) -> str:
    """The table column of a measured set: the same kind of set on another surface of the part
    (``ood_bands`` on the plain arm, ``ood_bands_fine`` on the subdivided one) or on another part
    (``belly_test`` on the belly, ``bodies_test`` on the arm: held-out bodies) shares it.
    """
    key = key[:-5] if key.endswith("_fine") else key
    return "bodies_" + key[6:] if key.startswith("belly_") else key


def brief(path=None) -> str:
    """The zoo in a table under 100 columns: each model's kind, part, tissue (the preset of its
    data; "pose in" for a model given an object's pose), size, and its relative
    MEE (%) on its in-distribution test split and over the other sets it was measured on (the
    range); ``stmpl zoo show NAME`` gives every figure.
    """
    rows = []
    for n, e in sorted(manifest(path)["models"].items()):
        metrics = {k: v for k, v in (e.get("metrics") or {}).items() if k != "val"}
        test = (metrics.pop("test", None) or {}).get("rel_mee", [None])[0]
        other = [v["rel_mee"][0] for v in metrics.values() if "rel_mee" in v]
        rows.append(
            [
                n,
                e["kind"],
                str(e.get("part") or "–"),
                _tissue(e),
                f"{e['bytes'] / 1e6:.2f}",
                "–" if test is None else f"{test:.2f}",
                "–" if not other else f"{min(other):.2f}-{max(other):.2f} ({len(other)} sets)",
            ]
        )
    head = ["model", "kind", "part", "tissue", "MB", "test rel. MEE %", "other sets rel. MEE %"]
    return markdown(head, rows, "llllrrr")


def show(name: str, path=None) -> str:
    """Every figure of zoo model ``name``, one line each: what it is, how it was made, and per
    measured set its MEE (mm), relative MEE (%) and peak error (%).
    """
    e = entry(name, path)
    ds = e.get("dataset") or {}
    trained = e.get("trained") or {}
    lines = [
        f"{name}: {e['kind']}, {e.get('parameters') or 0:,} parameters, "
        f"{e['bytes'] / 1e6:.2f} MB ({e['file']})",
        f"  part: {e.get('part')}",
        f"  tissue: {ds.get('tissue', 'paper')}; takes "
        + ("an object's pose" if (e.get("config") or {}).get("given") == "pose" else "a force"),
        f"  trained on: {ds.get('name')} (content hash {ds.get('hash')})",
    ]
    lines += [f"  {k}: {v}" for k, v in trained.items() if v]
    for k, t in sorted((e.get("metrics") or {}).items()):
        if "mee" not in t:
            continue
        peak = t.get("peak_err", [float("nan")])[0]
        label = LABELS.get(_column(k), k)
        reaction = t.get("reaction_err", [None])[0]  # a pose model's reaction against the FEM's
        lines.append(
            f"  {label if label == k else f'{label} ({k})'}: MEE {t['mee'][0]:.4f} mm, relative "
            f"{t['rel_mee'][0]:.2f} %, peak "
            + ("–" if peak != peak else f"{peak:+.1f} %")
            + ("" if reaction is None else f", reaction {reaction:+.1f} %")
        )
    for axis, lim in (e.get("limits") or {}).items():
        lines.append(f"  capped: {axis} <= {lim['max']:g} ({lim.get('source', '')})")
    return "\n".join(lines) + "\n"


def table(path=None) -> str:
    """A markdown table of the zoo: name, kind, size, training dataset, tissue, and on the test
    split of every kind of dataset it was measured on the MEE (mm), the relative MEE (%) and the
    mean error of the peak displacement (%); a set a model was not measured on is a dash.
    """
    models = manifest(path)["models"]
    cols = sorted(
        {
            _column(k)
            for e in models.values()
            for k in (e.get("metrics") or {})
            if k not in ("val",)
        },
        key=lambda k: (list(LABELS).index(k) if k in LABELS else len(LABELS), k),
    )
    head = ["model", "kind", "parameters", "MB", "trained on", "tissue"] + [
        f"{LABELS.get(k, k)}: MEE mm / rel. % / peak %" for k in cols
    ]
    rows = []
    for n, e in sorted(models.items()):
        ds = e.get("dataset") or {}
        metrics = {_column(k): v for k, v in (e.get("metrics") or {}).items()}
        cells = []
        for k in cols:
            t = metrics.get(k) or {}
            if "mee" not in t:
                cells.append("–")
                continue
            peak = t.get("peak_err", [float("nan")])[0]
            cells.append(
                f"{t['mee'][0]:.4f} / {t['rel_mee'][0]:.2f} / "
                + ("–" if peak != peak else f"{peak:+.1f}")
            )
        rows.append(
            [
                n,
                e["kind"],
                f"{e.get('parameters') or 0:,}",
                f"{e['bytes'] / 1e6:.2f}",
                f"{ds.get('name')} ({ds.get('hash')})",
                _tissue(e),
                *cells,
            ]
        )
    return markdown(head, rows, "llrrll" + "r" * len(cols))


def _tissue(e: dict) -> str:
    """A zoo entry's tissue: its data's preset, and whether the model takes a pose."""
    tissue = (e.get("dataset") or {}).get("tissue", "paper")
    return tissue + (", pose in" if (e.get("config") or {}).get("given") == "pose" else "")
