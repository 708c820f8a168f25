"""The Newton solver's settings (:class:`SolverOptions`), checked when made."""

from __future__ import annotations

from dataclasses import dataclass

from fem.linear_solvers import LINEAR_SOLVERS


@dataclass(frozen=True)
class SolverOptions:
    """Newton settings.

    Attributes:
        rtol: converged when ``|r| <= rtol * |f|`` (free DOFs).
        max_iter: Newton iterations per solve (per force level or sub-step).
        reuse: keep the factorised tangent while the residual falls at least this much per
            step (0 for plain Newton: a new factorisation every step).
        stagnation: fail when the residual has not halved over this many iterations.
        max_substeps: a failed force increment is halved up to this many times.
        max_compression: reject states whose skin moves inward by more than this share of the
            local thickness (1.0: skin reaches bone).
        linear_solver: ``"auto"``, ``"pardiso"``, ``"pardiso_single"`` (factorised in single
            precision, solves refined in double), ``"superlu"`` or ``"cg"`` (AMG-preconditioned).
        force_mode: how per-vertex forces become nodal forces, ``"traction"`` or ``"nodal"``
            (see :meth:`ShellMesh.nodal_forces`).
        rims: ``"fixed"`` holds the part's cut rims (all layers) where the tissue would go on
            into the rest of the body; ``"free"`` leaves the cut faces traction-free.
        volume: where a law's volume part is evaluated: ``"mean"`` on each element's mean
            volume ratio (mean dilatation, no volumetric locking; laws with a bulk modulus),
            ``"point"`` at every quadrature point, ``"auto"`` mean where the law allows it.
    """

    rtol: float = 1e-7
    max_iter: int = 40
    reuse: float = 0.1
    stagnation: int = 6
    max_substeps: int = 3
    max_compression: float = 1.0
    linear_solver: str = "auto"
    force_mode: str = "traction"
    rims: str = "fixed"
    volume: str = "auto"

    def __post_init__(self) -> None:
        if self.linear_solver not in ("auto", *LINEAR_SOLVERS):
            raise ValueError(
                f"unknown linear_solver {self.linear_solver!r}; choose auto or one "
                f"of {sorted(LINEAR_SOLVERS)}"
            )
        if self.force_mode not in ("traction", "nodal"):
            raise ValueError(f"unknown force_mode {self.force_mode!r}; use 'traction' or 'nodal'")
        if self.volume not in ("auto", "mean", "point"):
            raise ValueError(f"volume must be 'auto', 'mean' or 'point', got {self.volume!r}")
        if self.rims not in ("fixed", "free"):
            raise ValueError(f"rims must be 'fixed' or 'free', got {self.rims!r}")
        if not (self.rtol > 0 and self.max_iter >= 1 and self.max_compression > 0):
            raise ValueError("rtol, max_iter and max_compression must be positive")
