"""Checked configs: one mechanism for every YAML config (datasets, training).

:func:`read` turns a YAML file or a mapping into a complete config over its defaults, refusing
broken YAML, a non-mapping and unknown keys with an error that names them; the small checks
(:func:`integer`, :func:`number`, :func:`one_of`) give every loader the same messages and refuse
what YAML makes by accident (``true`` where a number belongs).
"""

from __future__ import annotations

import copy
import os
import pathlib

import yaml


def read(source, defaults: dict, what: str, merge: tuple = (), name: str = "config") -> dict:
    """A complete config from a YAML path or a mapping: ``defaults`` overridden by the source's
    keys (the mappings named in ``merge`` are merged one level deep instead of replaced). An
    unset ``name`` becomes the file's stem (``name`` for a mapping). ``what`` names the config
    in errors ("dataset config", "training config").
    """
    if isinstance(source, (str, os.PathLike)):
        path = pathlib.Path(source)
        if not path.is_file():
            raise FileNotFoundError(f"{what} file not found: {path}")
        try:
            raw = yaml.safe_load(path.read_text())
        except (yaml.YAMLError, UnicodeDecodeError) as e:
            first = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
            raise ValueError(f"{what} {path} is not valid YAML: {first}") from e
        raw = {} if raw is None else raw
        default_name = path.stem
    else:
        raw, default_name = source, name
    if not isinstance(raw, dict):
        raise ValueError(f"a {what} must be a mapping of keys to values, got {type(raw).__name__}")
    unknown = set(raw) - set(defaults)
    if unknown:
        raise ValueError(f"unknown {what} keys {sorted(unknown)}; allowed: {sorted(defaults)}")
    cfg = copy.deepcopy(defaults)
    for k, v in raw.items():
        if k in merge and isinstance(v, dict) and isinstance(cfg[k], dict):
            cfg[k] = {**cfg[k], **copy.deepcopy(v)}
        else:
            cfg[k] = copy.deepcopy(v)
    if "name" in defaults:
        cfg["name"] = cfg["name"] or default_name
    return cfg


def integer(value, name: str, minimum: int | None = None) -> int:
    """``value`` if it is an integer (not a bool) of at least ``minimum``; else ``ValueError``."""
    if (
        isinstance(value, bool)
        or not isinstance(value, int)
        or (minimum is not None and value < minimum)
    ):
        bound = f" >= {minimum}" if minimum is not None else ""
        raise ValueError(f"{name} must be an integer{bound}, got {value!r}")
    return value


def number(
    value,
    name: str,
    low: float | None = None,
    high: float | None = None,
    low_open: bool = False,
    unit: str = "",
) -> float:
    """``value`` as a float if it is a finite number (not a bool) in the range; else
    ``ValueError`` naming the key. ``low_open``: ``low`` itself is excluded.
    """
    ok = not isinstance(value, bool) and isinstance(value, (int, float))
    if ok:
        x = float(value)
        ok = x == x and abs(x) != float("inf")
        if ok and low is not None:
            ok = x > low if low_open else x >= low
        if ok and high is not None:
            ok = x <= high
    if not ok:
        lo = "" if low is None else (f" > {low:g}" if low_open else f" >= {low:g}")
        hi = "" if high is None else f" <= {high:g}"
        rng = lo + ("," if lo and hi else "") + hi
        raise ValueError(
            f"{name} must be a number{rng}{(' ' + unit) if unit else ''}, got {value!r}"
        )
    return float(value)


def one_of(value, name: str, choices) -> str:
    """``value`` if it is one of ``choices``; else ``ValueError`` listing them."""
    if isinstance(value, (list, dict)) or value not in choices:
        raise ValueError(f"{name} must be one of {list(choices)}, got {value!r}")
    return value
