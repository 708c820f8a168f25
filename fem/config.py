"""The dataset config (``configs/data/*.yaml``): its keys, their defaults and checks, and the
hash of what decides the samples. Read with :func:`read_config`; unknown keys are errors.
"""

from __future__ import annotations

import hashlib
import json
import os
import pathlib

import numpy as np
import yaml

from fem.bodies import check_bodies
from fem.layers import preset, read_tissue
from fem.material import material
from fem.shapes import PRESSES
from fem.simulate import check_order, resolution
from fem.solver import SolverOptions
from stmpl import config as checked
from stmpl.body.spec import check_spec
from stmpl.fidelity import FIDELITIES
from stmpl.tissue import THICKNESS_RANGE

DEFAULTS = {
    "name": None,
    "body": {"model": "anny"},
    "part": "left_arm",
    "thickness_mm": [5.0, 7.5, 10.0],
    "material": {"name": "neo_hookean", "E": 1000.0, "nu": 0.4},
    "tissue": "paper",
    "resolution": "reference",
    "fidelity": "full",
    "forces": [0.25, 0.5, 0.75, 1.0],
    "max_pressure": 2000.0,
    "placements": {},
    "splits": [0.8, 0.1, 0.1],
    "seed": 0,
    "shard_tasks": 4,
    "solver": {},
    "parallel": {"backend": "processes", "workers": 2, "scheduler": None},
    "linear": False,
    "bodies": None,
    "friction": 0.0,
    "thickness_cycle": False,
    "force_tolerance": 0.01,
}
OPTIONAL = {
    "fidelity": "full",
    "linear": False,
    "bodies": None,
    "tissue": "paper",
    "friction": 0.0,
    "thickness_cycle": False,
    "force_tolerance": 0.01,
}
"""Keys whose default leaves a config's hash as it was before the key existed."""
"""``bodies``: ``phenotypes`` (a list of anny phenotypes), ``sample`` (``{count, seed, age}``:
that many drawn from anny's shape distribution, adults of ``age`` [lo, hi] years), or for an
SMPL-format body ``betas`` (a list of shape vectors); ``thickness`` (``from_weight``, the
paper's heuristic per body through anny's weight or SMPL's beta_2, or ``levels``:
``thickness_mm`` on every body); see :mod:`fem.bodies`."""
PLACEMENT_KEYS = {
    "disk": {"centres", "skip", "radii"},
    "ellipse": {"centres", "skip", "semi_axes", "angles"},
    "seam_disk": {"at", "radii"},
    "spots": {"centres", "skip", "counts", "radii", "spread"},
    "band": {"at", "widths"},
    "letter": {"chars", "uv", "heights", "strokes", "angles"},
    "grasp": {"along", "around", "grips", "hand_heights", "depth"},
    "palm": {"uv", "spins", "hand_heights", "depth"},
    "press_disk": {"centres", "skip", "radii", "rounding"},
    "press_sphere": {"centres", "skip", "radii"},
    "press_grip": {"along", "around", "grips"},
}
PLACEMENT_VALUES = {
    "centres": "count",
    "skip": "skip",
    "spread": "number",
    "depth": "number",
    "rounding": "number",
    "uv": "pairs",
    "semi_axes": "pairs",
    "chars": "strings",
    "grips": "strings",
    "counts": "counts",
}
"""What each placement key holds; any other key is a list of numbers."""
BACKENDS = ("serial", "processes", "dask")
# FIDELITIES (stmpl.predictor): ``full`` solves the whole part; ``auto`` the patch the load
# moves (:mod:`fem.local`)


def read_config(source) -> dict:
    """A checked, completed dataset config from a YAML path or a dict."""
    cfg = checked.read(source, DEFAULTS, "dataset config", merge=("parallel",), name="dataset")
    if isinstance(cfg["tissue"], str) and cfg["tissue"].endswith((".yaml", ".yml")):
        cfg["tissue"] = read_tissue(cfg["tissue"])  # the layers themselves decide the samples
    check(cfg)
    return cfg


NOTED = ("forces", "thickness_mm")
"""Keys that decide the samples and whose defaults a config rarely means to take: a config
that leaves them out is told what was used."""


def defaulted(source) -> list[str]:
    """Of :data:`NOTED`, the keys a config (a YAML path or a mapping) leaves to the defaults,
    each as ``"key: value"``.
    """
    raw = source
    if isinstance(source, (str, os.PathLike)):
        raw = yaml.safe_load(pathlib.Path(source).read_text()) or {}
    return [f"{k}: {DEFAULTS[k]}" for k in NOTED if k not in raw]


def _numbers(values, name: str) -> np.ndarray:
    """A 1-D float array of ``values`` (a non-empty list of numbers, no bools)."""
    if (
        not isinstance(values, (list, tuple))
        or not values
        or any(isinstance(x, bool) or not isinstance(x, (int, float)) for x in values)
    ):
        raise ValueError(f"{name} must be a non-empty list of numbers, got {values!r}")
    return np.asarray(values, dtype=float)


def check(cfg: dict) -> None:
    """Raise ``ValueError`` naming the first key of ``cfg`` that is out of place."""
    check_spec(cfg["body"])
    if not isinstance(cfg["part"], str):
        raise ValueError(f"part must be a part name, got {cfg['part']!r}")
    th = _numbers(cfg["thickness_mm"], "thickness_mm")
    lo, hi = (1e3 * x for x in THICKNESS_RANGE)
    if not np.all((th >= lo) & (th <= hi)):
        raise ValueError(
            f"thickness_mm must be a list of values in [{lo}, {hi}] mm, got {cfg['thickness_mm']}"
        )
    f = _numbers(cfg["forces"], "forces")
    if not np.all(np.isfinite(f)) or f.min() <= 0 or np.any(np.diff(f) <= 0):
        raise ValueError(f"forces must be a rising list of totals > 0 N, got {cfg['forces']}")
    checked.number(cfg["max_pressure"], "max_pressure", 0, low_open=True, unit="Pa")
    _check_placements(cfg["placements"])
    s = _numbers(cfg["splits"], "splits")
    if s.shape != (3,) or s.min() < 0 or abs(s.sum() - 1) > 1e-9:
        raise ValueError(
            f"splits must be three shares (train, val, test) summing to 1, got {cfg['splits']}"
        )
    checked.integer(cfg["seed"], "seed", 0)
    checked.integer(cfg["shard_tasks"], "shard_tasks", 1)
    par = cfg["parallel"]
    if not isinstance(par, dict) or set(par) - set(DEFAULTS["parallel"]):
        raise ValueError(f"parallel takes keys {sorted(DEFAULTS['parallel'])}, got {par!r}")
    checked.one_of(par["backend"], "parallel.backend", BACKENDS)
    checked.integer(par["workers"], "parallel.workers", 1)
    _check_setup(cfg)
    _check_tissue(cfg)
    checked.one_of(cfg["fidelity"], "fidelity", FIDELITIES)
    _check_presses(cfg)
    if not isinstance(cfg["thickness_cycle"], bool):
        raise ValueError(f"thickness_cycle must be true or false, got {cfg['thickness_cycle']!r}")
    for kind, spec in cfg["placements"].items():
        if spec.get("skip", 0) >= spec.get("centres", 8):
            raise ValueError(
                f"placements.{kind}.skip {spec['skip']} leaves none of its "
                f"{spec.get('centres', 8)} centres"
            )
    if not isinstance(cfg["linear"], bool):
        raise ValueError(f"linear must be true or false, got {cfg['linear']!r}")
    if cfg["bodies"] is not None:
        check_bodies(cfg)


def _check_presses(cfg: dict) -> None:
    """The keys that only pressed objects read: ``fidelity`` (full), ``friction``,
    ``force_tolerance`` and ``linear`` (none).
    """
    presses = sorted(set(cfg["placements"]) & set(PRESSES))
    if presses and cfg["fidelity"] != "full":
        raise ValueError(
            f"fidelity {cfg['fidelity']}: {', '.join(presses)} are solved on the whole part "
            "(fidelity: full)"
        )
    checked.number(cfg["friction"], "friction", 0, unit="(Coulomb's coefficient, fem.friction)")
    if cfg["friction"] and not presses:
        raise ValueError(
            f"friction {cfg['friction']:g}: only pressed objects ({', '.join(PRESSES)}) rub on "
            "the skin; the config has none"
        )
    tol = cfg["force_tolerance"]
    if isinstance(tol, bool) or not isinstance(tol, (int, float)) or not 0 < tol < 0.5:
        raise ValueError(f"force_tolerance must be a share of each force in (0, 0.5), got {tol!r}")
    if tol != DEFAULTS["force_tolerance"] and not presses:
        raise ValueError(
            f"force_tolerance {tol:g}: only pressed objects ({', '.join(PRESSES)}) are driven to "
            "their forces by force control; the config has none"
        )
    if presses and cfg["linear"]:
        raise ValueError(f"linear: {', '.join(presses)} have no linear FEM answer (linear: false)")


def _check_placements(pl) -> None:
    """``placements``: a mapping of known load kinds to their known keys."""
    if not isinstance(pl, dict) or not pl:
        raise ValueError(f"placements must name at least one load kind: {sorted(PLACEMENT_KEYS)}")
    for kind, spec in pl.items():
        if kind not in PLACEMENT_KEYS:
            raise ValueError(f"unknown placement kind {kind!r}; use {sorted(PLACEMENT_KEYS)}")
        if not isinstance(spec, dict) or set(spec) - PLACEMENT_KEYS[kind]:
            raise ValueError(
                f"placements.{kind} takes keys {sorted(PLACEMENT_KEYS[kind])}, got {spec!r}"
            )
        for key, value in spec.items():
            _check_placement_value(value, f"placements.{kind}.{key}", PLACEMENT_VALUES.get(key))


def _check_placement_value(value, name: str, holds: str | None) -> None:
    """One placement key's value: a count, a finite number, or a non-empty list of numbers,
    counts, ``[a, b]`` pairs or strings (``holds``; ``None``: numbers).
    """
    if holds == "count":
        checked.integer(value, name, 1)
        return
    if holds == "number":
        checked.number(value, name)
        return
    if holds == "skip":
        checked.integer(value, name, 0)
        return
    what = {
        "pairs": "[a, b] pairs of numbers",
        "strings": "strings",
        "counts": "integers >= 1",
    }.get(holds, "numbers")
    if not isinstance(value, list) or not value:
        raise ValueError(f"{name} must be a non-empty list of {what}, got {value!r}")
    for x in value:
        if holds == "strings":
            ok = isinstance(x, str) and x.strip() != ""
        elif holds == "counts":
            ok = isinstance(x, int) and not isinstance(x, bool) and x >= 1
        elif holds == "pairs":
            ok = isinstance(x, list) and len(x) == 2 and all(_finite(v) for v in x)
        else:
            ok = _finite(x)
        if not ok:
            raise ValueError(f"{name} must be a non-empty list of {what}, got {value!r}")


def _finite(x) -> bool:
    """Whether ``x`` is a finite number (not a bool)."""
    return isinstance(x, (int, float)) and not isinstance(x, bool) and np.isfinite(x)


def _check_setup(cfg: dict) -> None:
    """The FEM set-up: ``material`` and ``solver`` build, ``resolution`` is one."""
    if not isinstance(cfg["material"], dict) or not isinstance(cfg["solver"], dict):
        raise ValueError("material and solver must be mappings")
    for key, make in (("material", material), ("solver", SolverOptions)):
        try:
            make(**cfg[key])
        except TypeError as e:
            raise ValueError(f"{key}: {e}") from e
    resolution(cfg["resolution"])


def _check_tissue(cfg: dict) -> None:
    """``tissue``: ``paper`` (the gel of ``material``), a layered preset or a tissue file's
    layers (:func:`fem.layers.from_mapping`), which bring their own laws (``material`` then
    stays at its default) and have no linear FEM yet.
    """
    if not isinstance(cfg["tissue"], (str, dict)):
        raise ValueError(
            f"tissue must be a preset name or a mapping of layers, got {cfg['tissue']!r}"
        )
    stack = preset(cfg["tissue"])
    if stack is None:
        return
    if cfg["material"] != DEFAULTS["material"]:
        raise ValueError(
            f"the {stack.name} tissue brings its own laws: remove material from the config"
        )
    if cfg["linear"]:
        raise ValueError(f"linear: the linear FEM of the layered {stack.name} tissue is not built")
    check_order(stack, cfg["resolution"])


def config_hash(cfg: dict) -> str:
    """Hash of everything that decides the samples (not how they are computed in parallel)."""
    key = {k: v for k, v in cfg.items() if k not in ("parallel", "name")}
    for k, default in OPTIONAL.items():  # defaults: hashes from before the key existed hold
        if k in key and key[k] == default:
            del key[k]
    return hashlib.sha256(json.dumps(key, sort_keys=True).encode()).hexdigest()[:16]
