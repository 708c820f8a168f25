"""Closed forms for rigid indenters on elastic layers, and the slab the FEM meets them on.

Rigid frictionless indenters at small depth ``delta`` (m), ``E* = E / (1 - nu^2)`` (Pa):

- Hertz, a sphere of radius ``R`` on a half-space: ``F = 4/3 E* R^(1/2) delta^(3/2)``, contact
  radius ``a = (R delta)^(1/2)``.
- A flat punch of radius ``a`` on a layer of thickness ``h`` bonded to a rigid base (Hayes,
  Keer, Herrmann & Mockros 1972, J. Biomech. 5:541): ``F = 2 E* a delta kappa(a/h, nu)``;
  ``kappa -> 1`` as ``a/h -> 0`` (Sneddon's half-space punch). ``kappa`` is the integral over
  ``[0, 1]`` of ``phi``, the solution of the Fredholm equation of the second kind

      phi(t) - 1/pi int_0^1 phi(x) (K(x - t) + K(x + t)) dx = 1,
      K(y) = tau int_0^inf k(u) cos(tau y u) du,  tau = a / h,
      k(u) = 1 - (2 eta sinh 2u - 4u) / (2 eta cosh 2u + 1 + eta^2 + 4u^2),  eta = 3 - 4 nu,

  solved here by Gauss-Legendre quadrature (Nystrom's method).
- A sphere on a bonded incompressible layer (Dimitriadis et al. 2002, Biophys. J. 82:2798):
  ``F = 16/9 E R^(1/2) delta^(3/2) (1 + 1.133 chi + 1.283 chi^2 + 0.769 chi^3 + 0.0975 chi^4)``,
  ``chi = (R delta)^(1/2) / h``.

:func:`quarter_slab` builds the layer these hold on: a quarter of a disk (the two symmetry planes
``x = 0`` and ``y = 0``) whose rings are circles, one of them at the punch's rim.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from fem.material import NeoHookean, Yeoh, lame
from fem.mesh import ShellMesh, shell_mesh
from fem.options import SolverOptions
from fem.solver import Solver
from stmpl.body.extract import normalise_chart
from stmpl.body.primitives import grid, tube
from stmpl.part import BodyPart


def hertz_force(E: float, nu: float, R: float, delta: float) -> float:
    """Hertz: a rigid sphere of radius ``R`` (m) pressed ``delta`` (m) into a half-space, N."""
    return 4.0 / 3.0 * E / (1 - nu**2) * np.sqrt(R) * delta**1.5


def dimitriadis_force(E: float, R: float, delta: float, h: float) -> float:
    """A rigid sphere pressed ``delta`` (m) into an incompressible layer of thickness ``h``
    (m) bonded to a rigid base (Dimitriadis et al. 2002), N.
    """
    chi = np.sqrt(R * delta) / h
    series = 1 + 1.133 * chi + 1.283 * chi**2 + 0.769 * chi**3 + 0.0975 * chi**4
    return 16.0 / 9.0 * E * np.sqrt(R) * delta**1.5 * series


def _kernel(y: np.ndarray, tau: float, eta: float) -> np.ndarray:
    """``K(y) = tau int_0^inf k(u) cos(tau y u) du`` for each ``y``; ``k`` decays like
    ``u exp(-2u)``, so the integral ends where that is below round-off.
    """

    def k(u):
        return 1 - (2 * eta * np.sinh(2 * u) - 4 * u) / (
            2 * eta * np.cosh(2 * u) + 1 + eta**2 + 4 * u**2
        )

    from scipy.integrate import quad  # deferred: quadrature for a closed form only

    out = np.empty(len(y))
    for i, yi in enumerate(y):
        w = tau * abs(yi)
        value = quad(k, 0, 40, weight="cos", wvar=w, limit=400)[0] if w > 0 else quad(k, 0, 40)[0]
        out[i] = tau * value
    return out


def hayes_kappa(a_over_h: float, nu: float, points: int = 48) -> float:
    """Hayes et al.'s ``kappa(a/h, nu)`` for a flat punch on a bonded layer (module docstring):
    ``F / (2 E* a delta)``.
    """
    if not (a_over_h > 0 and -1 < nu < 0.5):
        raise ValueError(f"need a/h > 0 and nu in (-1, 0.5), got {a_over_h!r}, {nu!r}")
    x, w = np.polynomial.legendre.leggauss(points)
    x, w = 0.5 * (x + 1), 0.5 * w  # on [0, 1]
    eta = 3 - 4 * nu
    diffs = np.unique(np.round(np.abs(np.concatenate([x[:, None] - x, x[:, None] + x])), 14))
    table = dict(zip(diffs, _kernel(diffs, a_over_h, eta)))

    def K(y):
        return np.vectorize(lambda v: table[np.round(abs(v), 14)])(y)

    A = np.eye(points) - (K(x[None, :] - x[:, None]) + K(x[None, :] + x[:, None])) * w / np.pi
    phi = np.linalg.solve(A, np.ones(points))
    return float(w @ phi)


def quarter_disk(radii) -> BodyPart:
    """A flat quarter disk in the z = 0 plane (``x, y >= 0``) whose vertices stand on circles of
    the given ``radii`` (m, from 0, rising): square rings of a grid mapped onto circles, ring
    ``k`` holding ``2k + 1`` vertices; its straight edges lie on the symmetry planes.
    """
    r = np.asarray(radii, dtype=float)
    if r.ndim != 1 or len(r) < 2 or r[0] != 0 or np.any(np.diff(r) <= 0):
        raise ValueError("radii must start at 0 and rise strictly")
    n = len(r) - 1
    part = grid(np.arange(n + 1.0), np.arange(n + 1.0))
    i, j = part.vertices[:, 0], part.vertices[:, 1]
    ring = np.maximum(i, j)
    with np.errstate(invalid="ignore", divide="ignore"):
        theta = np.where(i >= j, np.pi / 4 * j / i, np.pi / 2 - np.pi / 4 * i / j)
    theta = np.nan_to_num(theta)
    rad = r[ring.astype(int)]
    v = np.stack([rad * np.cos(theta), rad * np.sin(theta), np.zeros_like(rad)], axis=1)
    uv, scale = normalise_chart(v[:, :2], v, part.faces, part.faces)
    return replace(part, vertices=v, uv=uv, uv_scale=scale, source={"body": "quarter disk"})


def graded(first: float, total: float, ratio: float) -> np.ndarray:
    """Steps from 0 to ``total`` starting at ``first`` and growing by ``ratio``: the node
    positions, ending exactly at ``total``.
    """
    out, step = [0.0], first
    while out[-1] + step < total * (1 - 1e-9):
        out.append(out[-1] + step)
        step *= ratio
    if total - out[-1] < 0.3 * step and len(out) > 1:
        out[-1] = total
    else:
        out.append(total)
    return np.array(out)


def quarter_slab(
    thickness: float,
    radius: float,
    rim: float,
    spacing: float,
    first_layer: float,
    ratio: float = 1.25,
) -> tuple[BodyPart, ShellMesh, np.ndarray]:
    """A bonded layer of ``thickness`` (m) over a quarter disk of ``radius`` (m): rings every
    2 ``spacing`` (m) out to 0.7 ``rim``, every ``spacing`` from there to 1.3 ``rim`` (one
    exactly at ``rim``, a punch's edge), then growing by ``ratio``; node layers from
    ``first_layer`` (m) under the skin growing by ``ratio``.
    Returns ``(part, mesh, fixed)``: ``fixed`` ``(M, 3)`` holds each symmetry plane's normal
    component and the far rim entirely (the base is held by the solver).
    """
    core = 0.7 * rim  # coarser inside, fine across the rim where the pressure is singular
    centre = np.linspace(0.0, core, max(2, round(core / (2 * spacing)) + 1))
    inner = np.linspace(core, rim, max(2, round((rim - core) / spacing) + 1))
    inner = np.concatenate([centre, inner[1:]])
    step = inner[-1] - inner[-2]
    outer = rim + graded(step, 0.3 * rim, 1.0)[1:]
    outer = np.concatenate([outer, outer[-1] + graded(step * ratio, radius - outer[-1], ratio)[1:]])
    part = quarter_disk(np.concatenate([inner, outer]))
    depth = graded(first_layer, thickness, ratio) / thickness
    mesh = shell_mesh(
        part,
        np.full(part.n_vertices, thickness),
        layers=len(depth) - 1,
        normal_smoothing=0,
        fractions=depth,
    )
    x, y = mesh.nodes[:, 0], mesh.nodes[:, 1]
    fixed = np.zeros((mesh.n_nodes, 3), bool)
    fixed[np.abs(x) < 1e-12, 0] = True
    fixed[np.abs(y) < 1e-12, 1] = True
    fixed[np.hypot(x, y) > radius * (1 - 1e-9)] = True
    return part, mesh, fixed


def punch_slab(
    a_over_h: float,
    spacing: float = 0.05,
    order: int = 2,
    first_layer: float = 0.0015,
    ratio: float = 1.4,
    nu: float = 0.45,
    volume: str = "point",
) -> tuple[Solver, float, float]:
    """Hayes et al.'s set-up ready to press: a bonded layer ``h`` = 1 cm thick of E = 1 kPa,
    a quarter disk reaching 5 thicknesses past a punch's rim at ``a = a_over_h h`` (m), mesh
    spacing ``spacing a`` across the rim (see :func:`quarter_slab`). ``volume="mean"``: the same
    neo-Hookean solid written as a tissue law (shape part ``C10 = mu / 2``, bulk modulus ``K``),
    its volume term by mean dilatation. Returns ``(solver, a, h)``.
    """
    h = 0.01
    a = a_over_h * h
    part, mesh, fixed = quarter_slab(h, a + 5 * h, a, spacing * a, first_layer, ratio)
    law = NeoHookean(1000.0, nu)
    if volume == "mean":
        mu, lam = lame(1000.0, nu)
        law = Yeoh(C10=mu / 2, K=lam + 2 * mu / 3)
    options = SolverOptions(rims="free", volume=volume)
    return Solver(mesh, law, fixed, options, order=order), a, h


def arm_tube() -> tuple:
    """``(part, thickness (N,), point (3,), normal (3,))``: an arm-sized tube (radius 35 mm,
    80 mm long) under 7.5 mm of skin and fat, and the skin point at its middle where the
    convergence studies press.
    """
    part = tube(radius=0.035, length=0.08, n_around=24, n_along=8)
    thickness = np.full(part.n_vertices, 0.0075)
    top = int(np.argmax(part.vertices[:, 0] - 10 * np.abs(part.vertices[:, 2] - 0.04)))
    return part, thickness, part.vertices[top], part.normals[top]
