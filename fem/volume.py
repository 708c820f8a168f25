"""The volume part of the nearly incompressible tissue laws, and which elements take it on
their mean volume ratio (mean dilatation) rather than at every quadrature point.

A tissue law splits its energy into a shape part and ``U(J) = K/4 (J^2 - 1 - 2 ln J)`` with
bulk modulus ``K`` (Pa). Where ``K`` is far above the shear modulus, ``U`` taken at every point
locks the elements; taken on each element's mean volume ratio it does not
(:mod:`fem.solver`).
"""

from __future__ import annotations

import numpy as np


def volumetric(K: np.ndarray, J: np.ndarray):
    """``(U, U', U'')`` of the volume part ``U(J) = K/4 (J^2 - 1 - 2 ln J)`` at volume ratios
    ``J`` ``(T,)`` with bulk moduli ``K`` ``(T,)`` (Pa): J/m^3, Pa, Pa; ``U = inf`` where
    ``J <= 0``.
    """
    with np.errstate(invalid="ignore", divide="ignore"):
        U = np.where(J > 0, 0.25 * K * (J**2 - 1 - 2 * np.log(J)), np.inf)
        return U, 0.5 * K * (J - 1 / J), 0.5 * K * (1 + 1 / J**2)


def shear_moduli(material, n_elements: int) -> np.ndarray:
    """``(T,)`` each element's initial shear modulus, Pa (a
    :class:`~fem.material.Layered` material's by layer).
    """
    laws = getattr(material, "laws", None)
    if laws is None:
        return np.full(n_elements, float(material.mu))
    return np.array([law.mu for law in laws], dtype=float)[np.asarray(material.layer)]


def bulk_moduli(material, n_elements: int) -> np.ndarray | None:
    """``(T,)`` each element's bulk modulus (Pa) when ``material`` splits into a shape part and
    a volume part ``U(J)`` (the tissue laws), else ``None`` (the compressible neo-Hookean and
    linear laws, whose volume terms are not separable).
    """
    split = getattr(material, "bulk_moduli", None)
    return None if split is None else split(n_elements)


NEARLY_INCOMPRESSIBLE = 100.0
"""Under ``volume="auto"`` (:class:`~fem.options.SolverOptions`) a layer takes mean dilatation
where its bulk modulus exceeds this many times its shear modulus (Poisson's ratio above 0.495:
the fat and the muscle); a more compressible one (the skin, K / mu 13) keeps its volume term at
every point, which one element through its depth needs to bend as it should (mean dilatation
there made a fingertip on the forearm 13 % softer with one skin element than with two)."""


def volume_split(material, n_elements: int, volume: str = "auto"):
    """``(bulk, point_bulk)``, each ``(T,)`` (Pa): the bulk modulus each element takes on its
    mean volume ratio (mean dilatation) and the one it takes at every quadrature point, 0
    where the other applies. ``volume``: ``"mean"`` for every element, ``"auto"`` where the
    law is nearly incompressible (:data:`NEARLY_INCOMPRESSIBLE`). ``None`` under ``"auto"`` for
    a material without a bulk modulus or with no nearly incompressible layer (the law is then
    evaluated as it stands); ``"mean"`` then raises or applies everywhere.
    """
    K = bulk_moduli(material, n_elements)
    if K is None:
        if volume == "mean":
            raise ValueError(
                f"mean dilatation needs laws with a bulk modulus (the tissue laws); "
                f"{type(material).__name__} has none"
            )
        return None
    mean = np.ones(len(K), bool)
    if volume == "auto":
        mean = K > NEARLY_INCOMPRESSIBLE * shear_moduli(material, len(K))
        if not mean.any():  # every element's volume at its points: the law as it stands
            return None
    return np.where(mean, K, 0.0), np.where(mean, 0.0, K)
