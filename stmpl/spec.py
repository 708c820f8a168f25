"""Predictors named on the command line: ``fem``, ``fem:<resolution>``, ``zoo:<name>`` or a
``.safetensors`` checkpoint path."""

from __future__ import annotations

import pathlib


def predictor_from_spec(spec: str, device: str = "cpu", res: str = "reference",
                        levels: int = 1):
    """The predictor ``spec`` names (see the module docstring); ``res`` and ``levels`` are the
    FEM's resolution (unless the spec names one) and continuation levels."""
    from stmpl import predictor, zoo

    if spec.startswith("zoo:"):
        return zoo.read(spec[4:], device=device)
    if spec == "fem" or spec.startswith("fem:"):
        return predictor.create("fem", res=spec.split(":", 1)[1] if ":" in spec else res,
                                levels=levels)
    path = pathlib.Path(spec)
    if path.suffix == ".safetensors" or path.exists():
        return predictor.read(path, device=device)
    raise ValueError(f"unknown predictor {spec!r}: give fem, fem:<resolution>, zoo:<name> or a "
                     ".safetensors checkpoint")


def label(spec: str) -> str:
    """A short name for a spec in tables and pictures: the zoo name, the checkpoint's stem or
    the spec itself."""
    if spec.startswith("zoo:"):
        return spec[4:]
    if spec.endswith(".safetensors"):
        return pathlib.Path(spec).stem
    return spec
