"""Predictors named on the command line: ``fem``, ``fem:<resolution>``, ``zoo:<name>`` or a
``.safetensors`` checkpoint path.
"""

from __future__ import annotations

import pathlib

from stmpl import predictor
from stmpl.checkpoint import read_sidecar
from stmpl.pipeline import zoo


def predictor_from_spec(
    spec: str,
    device: str = "cpu",
    res: str = "reference",
    levels: int = 1,
    fidelity: str = "full",
    tissue: str = "paper",
    phenotype: dict | None = None,
    friction: float = 0.0,
    engine: str = "default",
    **options,
):
    """The predictor ``spec`` names (see the module docstring); ``res`` and ``levels`` are the
    FEM's resolution (unless the spec names one) and continuation levels, ``tissue`` its tissue
    preset (its layers shaped by anny's ``phenotype``) and ``friction`` its Coulomb coefficient
    between a posed object and the skin; ``fidelity``
    (``full`` or ``auto``, :data:`stmpl.fidelity.FIDELITIES`) how much of the part it models;
    ``engine`` what runs a learned model (:data:`stmpl.predictor.ENGINES`); ``options`` go to
    a learned model's constructor (e.g. ``region_tolerance``).
    """
    predictor.check_fidelity(fidelity)
    if spec.startswith("zoo:"):
        return zoo.read(spec[4:], device=device, fidelity=fidelity, engine=engine, **options)
    if spec == "fem" or spec.startswith("fem:"):
        res = spec.split(":", 1)[1] if ":" in spec else res
        return predictor.create(
            "fem",
            res=res,
            levels=levels,
            fidelity=fidelity,
            tissue=tissue,
            phenotype=phenotype,
            friction=friction,
        )
    if pathlib.Path(spec).suffix == ".safetensors" or pathlib.Path(spec).exists():
        return predictor.read(spec, device=device, fidelity=fidelity, engine=engine, **options)
    raise ValueError(
        f"unknown predictor {spec!r}: give fem, fem:<resolution>, zoo:<name> or a "
        ".safetensors checkpoint"
    )


def key(spec: str) -> str:
    """What decides a spec's answers, for caches: a checkpoint's digest (a file's sidecar, or the
    zoo manifest's entry), or the spec itself (``fem:<res>``).
    """
    p = pathlib.Path(spec)
    if p.suffix == ".safetensors" and p.is_file():
        return read_sidecar(p)["digest"]
    if spec.startswith("zoo:"):
        return zoo.entry(spec[4:])["digest"]
    return spec


def label(spec: str) -> str:
    """A short name for a spec in tables and pictures: the zoo name, the checkpoint's stem or
    the spec itself.
    """
    if spec.startswith("zoo:"):
        return spec[4:]
    if spec.endswith(".safetensors"):
        return pathlib.Path(spec).stem
    return spec
