"""Hyperelastic materials evaluated on batches of deformation gradients.

A material maps ``F`` of shape ``(T, 3, 3)`` to the strain energy density ``W`` (J/m^3), the first
Piola-Kirchhoff stress ``P = dW/dF`` (Pa) and the tangent ``A = dP/dF`` of shape ``(T, 3, 3, 3, 3)``
(``A[t, i, J, k, L] = d P_iJ / d F_kL``). Lamé parameters from Young's modulus ``E`` and Poisson's
ratio ``nu``: ``mu = E / (2 (1 + nu))``, ``lam = E nu / ((1 + nu)(1 - 2 nu))``.

Compressible Neo-Hookean (``J = det F``, ``I1 = tr(F^T F)``)::

    W = mu/2 (I1 - 3) - mu ln J + lam/2 (ln J)^2
    P = mu (F - F^-T) + lam ln J F^-T
    A_iJkL = mu d_ik d_JL + lam Finv_Ji Finv_Lk + (mu - lam ln J) Finv_Li Finv_Jk

Linear elasticity (``eps = sym(F - I)``)::

    W = mu eps:eps + lam/2 tr(eps)^2
    P = 2 mu eps + lam tr(eps) I
    A_iJkL = mu (d_ik d_JL + d_iL d_Jk) + lam d_iJ d_kL

Both agree to first order at ``F = I``. The paper's defaults: ``E = 1 kPa``, ``nu = 0.4``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

_I = np.eye(3)


def det3(F: np.ndarray) -> np.ndarray:
    """``(T,)`` determinants of ``(T, 3, 3)`` matrices (closed form, faster than LAPACK here)."""
    return (
        F[:, 0, 0] * (F[:, 1, 1] * F[:, 2, 2] - F[:, 1, 2] * F[:, 2, 1])
        - F[:, 0, 1] * (F[:, 1, 0] * F[:, 2, 2] - F[:, 1, 2] * F[:, 2, 0])
        + F[:, 0, 2] * (F[:, 1, 0] * F[:, 2, 1] - F[:, 1, 1] * F[:, 2, 0])
    )


def inv3(F: np.ndarray):
    """``(F^-1 (T, 3, 3), det F (T,))`` by cofactors."""
    C = np.empty_like(F)
    C[:, 0, 0] = F[:, 1, 1] * F[:, 2, 2] - F[:, 1, 2] * F[:, 2, 1]
    C[:, 0, 1] = F[:, 0, 2] * F[:, 2, 1] - F[:, 0, 1] * F[:, 2, 2]
    C[:, 0, 2] = F[:, 0, 1] * F[:, 1, 2] - F[:, 0, 2] * F[:, 1, 1]
    C[:, 1, 0] = F[:, 1, 2] * F[:, 2, 0] - F[:, 1, 0] * F[:, 2, 2]
    C[:, 1, 1] = F[:, 0, 0] * F[:, 2, 2] - F[:, 0, 2] * F[:, 2, 0]
    C[:, 1, 2] = F[:, 0, 2] * F[:, 1, 0] - F[:, 0, 0] * F[:, 1, 2]
    C[:, 2, 0] = F[:, 1, 0] * F[:, 2, 1] - F[:, 1, 1] * F[:, 2, 0]
    C[:, 2, 1] = F[:, 0, 1] * F[:, 2, 0] - F[:, 0, 0] * F[:, 2, 1]
    C[:, 2, 2] = F[:, 0, 0] * F[:, 1, 1] - F[:, 0, 1] * F[:, 1, 0]
    J = F[:, 0, 0] * C[:, 0, 0] + F[:, 0, 1] * C[:, 1, 0] + F[:, 0, 2] * C[:, 2, 0]
    return C / J[:, None, None], J


def lame(E: float, nu: float) -> tuple[float, float]:
    """``(mu, lam)`` in Pa from Young's modulus ``E`` (Pa) and Poisson's ratio ``nu``."""
    if not (np.isfinite(E) and E > 0):
        raise ValueError(f"Young's modulus E must be > 0 Pa, got {E!r}")
    if not (np.isfinite(nu) and -1.0 < nu < 0.5):
        raise ValueError(f"Poisson's ratio nu must lie in (-1, 0.5), got {nu!r}")
    return E / (2 * (1 + nu)), E * nu / ((1 + nu) * (1 - 2 * nu))


@dataclass(frozen=True)
class Material:
    """An isotropic material given by ``E`` (Pa) and ``nu``; subclasses define ``energy`` and
    ``tangent_parts``, from which the stress and the full tangent follow.
    """

    E: float = 1000.0
    nu: float = 0.4
    name = "material"

    def __post_init__(self) -> None:
        lame(self.E, self.nu)

    @property
    def mu(self) -> float:
        return lame(self.E, self.nu)[0]

    @property
    def lam(self) -> float:
        return lame(self.E, self.nu)[1]

    def stress(self, F: np.ndarray) -> np.ndarray:
        """``(T, 3, 3)`` first Piola-Kirchhoff stress, Pa."""
        return self.tangent_parts(F)[0]

    def stress_tangent(self, F: np.ndarray, tangent: bool = True):
        """``(P, A)``: ``(T, 3, 3)`` stress and ``(T, 3, 3, 3, 3)`` tangent (``None`` unasked)."""
        P, parts = self.tangent_parts(F)
        return P, (tangent_from_parts(*parts) if tangent else None)


@dataclass(frozen=True)
class NeoHookean(Material):
    """Compressible Neo-Hookean solid. ``E`` in Pa, ``nu`` dimensionless; needs ``det F > 0``."""

    name = "neo_hookean"

    def energy(self, F: np.ndarray) -> np.ndarray:
        """``(T,)`` energy density, J/m^3; ``inf`` where ``det F <= 0``."""
        mu, lam = lame(self.E, self.nu)
        J = det3(F)
        with np.errstate(divide="ignore", invalid="ignore"):
            lnJ = np.log(J)
            W = 0.5 * mu * (np.einsum("tij,tij->t", F, F) - 3) - mu * lnJ + 0.5 * lam * lnJ**2
        return np.where(J > 0, W, np.inf)

    def tangent_parts(self, F: np.ndarray):
        """``(P, (a, b, c, H))`` with ``A_iJkL = a d_ik d_JL + b H_Ji H_Lk + c H_Li H_Jk``.

        For Neo-Hookean ``a = mu``, ``b = lam``, ``c = mu - lam ln J``, ``H = F^-1``; the solver
        contracts this form with shape-function gradients directly (no 81-entry tensor).
        """
        mu, lam = lame(self.E, self.nu)
        Finv, J = inv3(F)
        FinvT = Finv.transpose(0, 2, 1)
        lnJ = np.log(J)
        P = mu * (F - FinvT) + (lam * lnJ)[:, None, None] * FinvT
        T = len(F)
        return P, (np.full(T, mu), np.full(T, lam), mu - lam * lnJ, Finv)


@dataclass(frozen=True)
class LinearElastic(Material):
    """Small-strain isotropic linear elasticity written on ``F`` (for checks and light touches)."""

    name = "linear"

    def energy(self, F: np.ndarray) -> np.ndarray:
        """``(T,)`` energy density, J/m^3."""
        mu, lam = lame(self.E, self.nu)
        eps = 0.5 * (F + F.transpose(0, 2, 1)) - _I
        tr = np.trace(eps, axis1=1, axis2=2)
        return mu * np.einsum("tij,tij->t", eps, eps) + 0.5 * lam * tr**2

    def tangent_parts(self, F: np.ndarray):
        """As :meth:`NeoHookean.tangent_parts`: ``a = mu``, ``b = lam``, ``c = mu``, ``H = I``."""
        mu, lam = lame(self.E, self.nu)
        eps = 0.5 * (F + F.transpose(0, 2, 1)) - _I
        P = 2 * mu * eps + lam * np.trace(eps, axis1=1, axis2=2)[:, None, None] * _I
        T = len(F)
        return P, (np.full(T, mu), np.full(T, lam), np.full(T, mu), np.broadcast_to(_I, (T, 3, 3)))


def tangent_from_parts(a, b, c, H) -> np.ndarray:
    """``(T, 3, 3, 3, 3)`` tangent ``A_iJkL = a d_ik d_JL + b H_Ji H_Lk + c H_Li H_Jk``."""
    return (
        a[:, None, None, None, None] * np.einsum("ik,JL->iJkL", _I, _I)[None]
        + b[:, None, None, None, None] * np.einsum("tJi,tLk->tiJkL", H, H)
        + c[:, None, None, None, None] * np.einsum("tLi,tJk->tiJkL", H, H)
    )


MATERIALS = {"neo_hookean": NeoHookean, "linear": LinearElastic}


def material(name: str = "neo_hookean", E: float = 1000.0, nu: float = 0.4):
    """A material by name (``"neo_hookean"`` or ``"linear"``)."""
    if name not in MATERIALS:
        raise ValueError(f"unknown material {name!r}; choose one of {sorted(MATERIALS)}")
    return MATERIALS[name](E=E, nu=nu)
