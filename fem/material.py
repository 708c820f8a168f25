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

Tissue laws (:class:`Yeoh`, :class:`Demiray`) split the energy into a shape part on the
isochoric invariant ``Ib = J^(-2/3) I1`` and a volume part with bulk modulus ``K`` (Pa), as the
fits of in-vivo indentation report them (``C10`` and ``K``)::

    W = psi(Ib - 3) + U(J),    U(J) = K/4 (J^2 - 1 - 2 ln J)
    Yeoh:     psi(x) = C10 x + C20 x^2 + C30 x^3          (C20 = C30 = 0: neo-Hookean)
    Demiray:  psi(x) = a / (2 b) (exp(b x) - 1)            (stiffens exponentially)
    Exponential: psi(x) = c/2 x + k1 / (2 k2) (exp(k2 x^2) - 1)   (adipose tissue)

Their initial shear modulus is ``mu = 2 psi'(0)``. Any energy ``W(I1, J)`` has the tangent
``A_iJkL = a d_ik d_JL + b H_Ji H_Lk + c H_Li H_Jk + d F_iJ F_kL + e (F_iJ H_Lk + H_Ji F_kL)``
with ``a = 2 W_1``, ``b = J W_J + J^2 W_JJ``, ``c = -J W_J``, ``d = 4 W_11``, ``e = 2 J W_1J``
(subscripts: partial derivatives in ``I1`` and ``J``); the compressible Neo-Hookean law is the
case ``d = e = 0``, whose shorter form the solver keeps.

:class:`Layered` gives each element the law of its tissue layer (skin, fat, muscle...).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fem.kinematics import det3, inv3
from fem.limits import GEL, Limits

_I = np.eye(3)


def lame(E: float, nu: float) -> tuple[float, float]:
    """``(mu, lam)`` in Pa from Young's modulus ``E`` (Pa) and Poisson's ratio ``nu``."""
    if not (np.isfinite(E) and E > 0):
        raise ValueError(f"Young's modulus E must be > 0 Pa, got {E!r}")
    if not (np.isfinite(nu) and -1.0 < nu < 0.5):
        raise ValueError(f"Poisson's ratio nu must lie in (-1, 0.5), got {nu!r}")
    return E / (2 * (1 + nu)), E * nu / ((1 + nu) * (1 - 2 * nu))


class Law:
    """What every material gives from its ``tangent_parts``: the stress and the full tangent.
    ``limits`` (a :class:`~fem.limits.Limits`, or ``None``) bound where its answers are trusted.
    """

    limits = None

    def stress(self, F: np.ndarray) -> np.ndarray:
        """``(T, 3, 3)`` first Piola-Kirchhoff stress, Pa."""
        return self.tangent_parts(F)[0]

    def stress_tangent(self, F: np.ndarray, tangent: bool = True):
        """``(P, A)``: ``(T, 3, 3)`` stress and ``(T, 3, 3, 3, 3)`` tangent (``None`` unasked)."""
        P, parts = self.tangent_parts(F)
        return P, (tangent_from_parts(*parts) if tangent else None)


@dataclass(frozen=True)
class Material(Law):
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


@dataclass(frozen=True)
class NeoHookean(Material):
    """Compressible Neo-Hookean solid. ``E`` in Pa, ``nu`` dimensionless; needs ``det F > 0``.
    Trusted up to :data:`fem.limits.GEL` (where the paper's gel was measured to buckle); as a
    layer of a tissue file, the tissue's bounds apply instead.
    """

    name = "neo_hookean"
    limits = GEL

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


def tangent_from_parts(a, b, c, H, d=None, e=None, F=None) -> np.ndarray:
    """``(T, 3, 3, 3, 3)`` tangent ``A_iJkL = a d_ik d_JL + b H_Ji H_Lk + c H_Li H_Jk``, plus
    ``d F_iJ F_kL + e (F_iJ H_Lk + H_Ji F_kL)`` when given.
    """
    A = (
        a[:, None, None, None, None] * np.einsum("ik,JL->iJkL", _I, _I)[None]
        + b[:, None, None, None, None] * np.einsum("tJi,tLk->tiJkL", H, H)
        + c[:, None, None, None, None] * np.einsum("tLi,tJk->tiJkL", H, H)
    )
    if d is not None:
        A = A + d[:, None, None, None, None] * np.einsum("tiJ,tkL->tiJkL", F, F)
        A = A + e[:, None, None, None, None] * (
            np.einsum("tiJ,tLk->tiJkL", F, H) + np.einsum("tJi,tkL->tiJkL", H, F)
        )
    return A


def _invariant_parts(F, W1, WJ, W11, W1J, WJJ, Finv, J):
    """``(P, (a, b, c, H, d, e, F))`` of an energy ``W(I1, J)`` from its partial derivatives
    ``(T,)`` at ``F`` ``(T, 3, 3)`` (see the module's docstring).
    """
    FinvT = Finv.transpose(0, 2, 1)
    P = (2 * W1)[:, None, None] * F + (J * WJ)[:, None, None] * FinvT
    parts = (2 * W1, J * WJ + J**2 * WJJ, -J * WJ, Finv, 4 * W11, 2 * J * W1J, F)
    return P, parts


@dataclass(frozen=True)
class IsochoricLaw(Law):
    """A law ``W = psi(Ib - 3) + U(J)`` with bulk modulus ``K`` (Pa); subclasses give ``psi``
    and its first two derivatives (:meth:`shape`). Needs ``det F > 0``.
    """

    K: float = 0.0
    name = "isochoric"

    def _check(self, **positive) -> None:
        for key, value in positive.items():
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"{self.name}: {key} must be > 0, got {value!r}")

    def shape(self, x: np.ndarray):
        """``(psi, psi', psi'')`` at ``x = Ib - 3`` ``(T,)``, J/m^3."""
        raise NotImplementedError

    @property
    def mu(self) -> float:
        """Initial shear modulus, Pa: ``2 psi'(0)``."""
        return float(2 * self.shape(np.zeros(1))[1][0])

    @property
    def E(self) -> float:
        """Initial Young's modulus, Pa: ``9 K mu / (3 K + mu)``."""
        return 9 * self.K * self.mu / (3 * self.K + self.mu)

    @property
    def nu(self) -> float:
        """Initial Poisson's ratio: ``(3 K - 2 mu) / (2 (3 K + mu))``."""
        return (3 * self.K - 2 * self.mu) / (2 * (3 * self.K + self.mu))

    def _derivatives(self, F: np.ndarray, volume: bool = True):
        K = self.K if volume else 0.0
        Finv, J = inv3(F)
        I1 = np.einsum("tij,tij->t", F, F)
        with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
            s = np.cbrt(J) ** -2  # J^(-2/3)
            ds = -2.0 / 3.0 * s / J  # d s / d J
            d2s = 10.0 / 9.0 * s / J**2
            psi, p1, p2 = self.shape(s * I1 - 3.0)
            W1 = p1 * s
            WJ = p1 * I1 * ds + 0.5 * K * (J - 1 / J)
            W11 = p2 * s**2
            W1J = p2 * s * I1 * ds + p1 * ds
            WJJ = p2 * (I1 * ds) ** 2 + p1 * I1 * d2s + 0.5 * K * (1 + 1 / J**2)
        return Finv, J, psi, (W1, WJ, W11, W1J, WJJ)

    def energy(self, F: np.ndarray) -> np.ndarray:
        """``(T,)`` energy density, J/m^3; ``inf`` where ``det F <= 0``."""
        _, J, psi, _ = self._derivatives(F)
        with np.errstate(invalid="ignore", divide="ignore"):
            U = 0.25 * self.K * (J**2 - 1 - 2 * np.log(J))
        return np.where(J > 0, psi + U, np.inf)

    def tangent_parts(self, F: np.ndarray):
        """``(P, (a, b, c, H, d, e, F))``: the stress and the tangent's parts (module docstring)."""
        Finv, J, _, (W1, WJ, W11, W1J, WJJ) = self._derivatives(F)
        return _invariant_parts(F, W1, WJ, W11, W1J, WJJ, Finv, J)

    def shape_energy(self, F: np.ndarray) -> np.ndarray:
        """``(T,)`` the shape part ``psi(Ib - 3)`` alone, J/m^3; ``inf`` where ``det F <= 0``."""
        _, J, psi, _ = self._derivatives(F, volume=False)
        return np.where(J > 0, psi, np.inf)

    def shape_parts(self, F: np.ndarray):
        """As :meth:`tangent_parts`, of the shape part alone (the volume part left to the
        solver's mean dilatation).
        """
        Finv, J, _, (W1, WJ, W11, W1J, WJJ) = self._derivatives(F, volume=False)
        return _invariant_parts(F, W1, WJ, W11, W1J, WJJ, Finv, J)

    def bulk_moduli(self, n_elements: int) -> np.ndarray:
        """``(T,)`` every element's bulk modulus ``K``, Pa."""
        return np.full(n_elements, float(self.K))


@dataclass(frozen=True)
class Yeoh(IsochoricLaw):
    """Yeoh's law, ``psi = C10 x + C20 x^2 + C30 x^3`` (Pa each) on ``x = Ib - 3``, bulk modulus
    ``K`` (Pa); with ``C20 = C30 = 0`` the incompressible-fit neo-Hookean law (``mu = 2 C10``).
    Positive ``C20``, ``C30`` stiffen it as it is compressed or stretched.
    """

    C10: float = 0.0
    C20: float = 0.0
    C30: float = 0.0
    name = "yeoh"

    def __post_init__(self) -> None:
        self._check(C10=self.C10, K=self.K)
        if not (self.C20 >= 0 and self.C30 >= 0):
            raise ValueError(f"yeoh: C20 and C30 must be >= 0, got {self.C20!r}, {self.C30!r}")

    def shape(self, x):
        c1, c2, c3 = self.C10, self.C20, self.C30
        return (
            c1 * x + c2 * x**2 + c3 * x**3,
            c1 + 2 * c2 * x + 3 * c3 * x**2,
            2 * c2 + 6 * c3 * x,
        )


@dataclass(frozen=True)
class Demiray(IsochoricLaw):
    """Demiray's exponential law, ``psi = a / (2 b) (exp(b x) - 1)`` on ``x = Ib - 3``: ``a``
    (Pa) the initial shear modulus, ``b`` (dimensionless) how fast it stiffens; bulk modulus
    ``K`` (Pa).
    """

    a: float = 0.0
    b: float = 0.0
    name = "demiray"

    def __post_init__(self) -> None:
        self._check(a=self.a, b=self.b, K=self.K)

    def shape(self, x):
        ex = np.exp(self.b * x)
        return self.a / (2 * self.b) * (ex - 1), 0.5 * self.a * ex, 0.5 * self.a * self.b * ex


@dataclass(frozen=True)
class Exponential(IsochoricLaw):
    """An isotropic exponential law, ``psi = c/2 x + k1 / (2 k2) (exp(k2 x^2) - 1)`` on
    ``x = Ib - 3``: ``c`` (Pa) the initial shear modulus, ``k1`` (Pa) and ``k2``
    (dimensionless) the stiffening of the collagen around the cells, as fitted to human
    adipose tissue (Sommer et al. 2013); bulk modulus ``K`` (Pa).
    """

    c: float = 0.0
    k1: float = 0.0
    k2: float = 0.0
    name = "exponential"

    def __post_init__(self) -> None:
        self._check(c=self.c, k1=self.k1, k2=self.k2, K=self.K)

    def shape(self, x):
        with np.errstate(over="ignore"):  # a trial state far past any real one: energy inf
            ex = np.exp(self.k2 * x**2)
        return (
            0.5 * self.c * x + self.k1 / (2 * self.k2) * (ex - 1),
            0.5 * self.c + self.k1 * x * ex,
            self.k1 * ex * (1 + 2 * self.k2 * x**2),
        )


@dataclass(frozen=True, eq=False)
class Layered(Law):
    """Each element its own layer's law: ``laws`` (one per layer) and ``layer`` ``(T,)`` (the
    layer of each element, in the mesh's element order), and the tissue's trust bounds
    ``limits`` (:class:`~fem.limits.Limits`, or ``None``). Evaluated on ``F`` ``(T Q, 3, 3)``, ``Q``
    quadrature points per element in a row.
    """

    laws: tuple
    layer: np.ndarray
    limits: Limits | None = None
    name = "layered"

    def __post_init__(self) -> None:
        layer = np.asarray(self.layer)
        if layer.ndim != 1 or len(layer) == 0 or layer.min() < 0 or layer.max() >= len(self.laws):
            raise ValueError(
                f"layer must be (T,) indices into the {len(self.laws)} laws, got shape "
                f"{layer.shape} with values {layer.min(initial=0)}..{layer.max(initial=0)}"
            )

    @property
    def mu(self) -> float:
        """The stiffest layer's initial shear modulus, Pa."""
        return max(law.mu for law in self.laws)

    def _groups(self, F):
        q, rest = divmod(len(F), len(self.layer))
        if rest:
            raise ValueError(f"{len(F)} deformation gradients for {len(self.layer)} elements")
        of = np.repeat(np.asarray(self.layer), q)
        return [(law, np.flatnonzero(of == k)) for k, law in enumerate(self.laws)]

    def _densities(self, F: np.ndarray, method: str) -> np.ndarray:
        """``(T Q,)``: each layer's ``method`` (an energy density) on its own points."""
        W = np.empty(len(F))
        for law, at in self._groups(F):
            W[at] = getattr(law, method)(F[at])
        return W

    def _parts(self, F: np.ndarray, method: str):
        """Each layer's ``method`` (stress and tangent parts) on its own points, in the long
        form (a law of the short form adds no ``d``, ``e`` terms).
        """
        P = np.empty_like(F)
        parts = [np.zeros(len(F)) for _ in range(3)] + [np.empty_like(F)]
        parts += [np.zeros(len(F)), np.zeros(len(F)), F]
        for law, at in self._groups(F):
            Pk, pk = getattr(law, method)(F[at])
            P[at] = Pk
            for j, value in enumerate(pk[:4]):
                parts[j][at] = value
            if len(pk) == 7:
                parts[4][at], parts[5][at] = pk[4], pk[5]
        return P, tuple(parts)

    def energy(self, F: np.ndarray) -> np.ndarray:
        """``(T Q,)`` energy density, J/m^3."""
        return self._densities(F, "energy")

    def tangent_parts(self, F: np.ndarray):
        """The layers' stresses and tangent parts, element by element (the long form)."""
        return self._parts(F, "tangent_parts")

    def stress(self, F: np.ndarray) -> np.ndarray:
        """``(T Q, 3, 3)`` first Piola-Kirchhoff stress, Pa."""
        P = np.empty_like(F)
        for law, at in self._groups(F):
            P[at] = law.stress(F[at])
        return P

    def bulk_moduli(self, n_elements: int) -> np.ndarray | None:
        """``(T,)`` each element's bulk modulus ``K`` (Pa) when every layer's law splits into a
        shape part and a volume part ``U(J)`` (:class:`IsochoricLaw`), else ``None``.
        """
        if len(self.layer) != n_elements:
            raise ValueError(f"{n_elements} elements for a layering of {len(self.layer)}")
        if not all(isinstance(law, IsochoricLaw) for law in self.laws):
            return None
        return np.array([law.K for law in self.laws], dtype=float)[np.asarray(self.layer)]

    def shape_energy(self, F: np.ndarray) -> np.ndarray:
        """``(T Q,)`` the layers' shape parts alone, J/m^3 (:meth:`IsochoricLaw.shape_energy`)."""
        return self._densities(F, "shape_energy")

    def shape_parts(self, F: np.ndarray):
        """The stresses and tangent parts of the layers' shape parts alone
        (:meth:`IsochoricLaw.shape_parts`).
        """
        return self._parts(F, "shape_parts")


def uniaxial(law, stretch: float) -> tuple[float, float]:
    """The exact homogeneous uniaxial state of ``law`` at axial ``stretch`` (free sides):
    ``(nominal axial stress P_11 in Pa, lateral stretch)``, the lateral stretch found where
    the lateral stress vanishes.
    """

    def state(t):
        return law.stress(np.diag([stretch, t, t])[None].astype(float))[0]

    from scipy.optimize import brentq  # deferred: root finding for a closed form only

    guess = stretch**-0.5  # incompressible
    lo, hi = guess / 1.2, guess * 1.2
    while state(lo)[1, 1] * state(hi)[1, 1] > 0 and hi / lo < 100:
        lo, hi = lo / 1.2, hi * 1.2
    t = brentq(lambda t: state(t)[1, 1], lo, hi, xtol=1e-14, rtol=1e-14)
    return float(state(t)[0, 0]), float(t)


MATERIALS = {"neo_hookean": NeoHookean, "linear": LinearElastic}


def material(name: str = "neo_hookean", E: float = 1000.0, nu: float = 0.4):
    """A material by name (``"neo_hookean"`` or ``"linear"``)."""
    if name not in MATERIALS:
        raise ValueError(f"unknown material {name!r}; choose one of {sorted(MATERIALS)}")
    return MATERIALS[name](E=E, nu=nu)
