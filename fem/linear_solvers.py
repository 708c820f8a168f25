"""Sparse linear solvers for the Newton steps, one interface (``factor(K)``, ``solve(b)``,
``upper``: whether it wants only the upper triangle; ``direct``: whether ``solve`` applies a
fixed factorisation, which can then precondition later tangents): MKL PARDISO (Cholesky,
fastest), SciPy's SuperLU (always there) and AMG-preconditioned conjugate gradients. A
factorisation that meets a non-positive pivot raises :class:`IndefiniteTangent`.
"""

from __future__ import annotations

import glob
import os
import sys
import warnings

import numpy as np
from scipy.sparse.linalg import cg, splu


class IndefiniteTangent(ArithmeticError):
    """The tangent is not positive definite (the layer buckles or snaps through)."""


class _SuperLU:
    """SciPy's SuperLU with a minimum-degree ordering on ``A^T + A`` (always available)."""

    name, upper, direct = "superlu", False, True

    def factor(self, K):

        self._lu = splu(
            K.tocsc(),
            permc_spec="MMD_AT_PLUS_A",
            options={"SymmetricMode": True},
            diag_pivot_thresh=0.0,
        )
        neg = int(np.sum(self._lu.U.diagonal() <= 0))
        if neg:
            raise IndefiniteTangent(f"{neg} non-positive pivots")

    def solve(self, b):
        return self._lu.solve(b)


def _find_mkl() -> None:
    """Point pypardiso at MKL's runtime where pip puts it (``<prefix>/lib``): otherwise its
    first solver searches the whole environment for it, recursively (about 0.9 s, the largest
    part of a process's first small solve).
    """
    if os.environ.get("PYPARDISO_MKL_RT"):
        return
    for d in ("lib", "Lib", "Library/bin"):
        found = sorted(glob.glob(os.path.join(sys.prefix, d, "*mkl_rt*")), key=len)
        if found:
            os.environ["PYPARDISO_MKL_RT"] = found[0]
            return


class _Pardiso:
    """MKL PARDISO through pypardiso, in symmetric positive definite (Cholesky) mode: the fastest
    factorisation here, and a failed one (error -4, zero or negative pivot) reports an
    indefinite tangent. The symbolic analysis is done once per pattern and reused.
    """

    name, upper, direct = "pardiso", True, True

    def __init__(self):
        _find_mkl()
        import pypardiso  # deferred: an optional linear solver (MKL)

        self._error = pypardiso.pardiso_wrapper.PyPardisoError
        self._solver = pypardiso.PyPardisoSolver(mtype=2)
        # pypardiso globs the environment for MKL on every construction (0.5 s): once is enough
        os.environ.setdefault("PYPARDISO_MKL_RT", self._solver.libmkl._name)
        self._analysed = None

    def __del__(self):
        try:  # release PARDISO's internal memory (factors) with the solver
            if self._analysed is not None:
                self._solver.free_memory(everything=True)
        except Exception:  # noqa: BLE001 - interpreter shutdown
            pass

    def factor(self, K):
        s = self._solver
        s._check_A(K)
        key = (K.shape, K.nnz)  # one Solver keeps one pattern
        b = np.zeros((K.shape[0], 1), order="F")
        try:
            if self._analysed != key:
                s.set_phase(11)
                s._call_pardiso(K, b)
                self._analysed = key
            s.set_phase(22)
            s._call_pardiso(K, b)
        except self._error as e:
            if "-4" in str(e):
                raise IndefiniteTangent("Cholesky factorisation met a non-positive pivot") from e
            raise RuntimeError(f"PARDISO failed: {e}") from e
        self._K = K

    def solve(self, b):
        """``x`` for ``b`` of shape ``(n,)`` or ``(n, k)`` (k right-hand sides at once)."""
        s = self._solver
        s.set_phase(33)
        x = s._call_pardiso(self._K, np.asfortranarray(b.reshape(len(b), -1)))
        return x.reshape(b.shape)


class _AMGCG:
    """Conjugate gradients preconditioned by smoothed-aggregation AMG (pyamg)."""

    name, upper, direct = "cg", False, False

    def factor(self, K):
        import pyamg  # deferred: an optional linear solver

        self._K = K
        self._M = pyamg.smoothed_aggregation_solver(K, symmetry="symmetric").aspreconditioner()

    def solve(self, b):

        if b.ndim == 2:
            return np.stack([self.solve(c) for c in b.T], axis=1)
        x, info = cg(self._K, b, rtol=1e-10, maxiter=2000, M=self._M)
        if info != 0:
            raise RuntimeError(f"AMG-CG did not converge (info {info})")
        return x


LINEAR_SOLVERS = {"pardiso": _Pardiso, "superlu": _SuperLU, "cg": _AMGCG}


def available_linear_solvers() -> list[str]:
    """Names of the linear solvers that import on this machine, fastest first."""
    out = []
    for name, mod in (("pardiso", "pypardiso"), ("superlu", None), ("cg", "pyamg")):
        if mod is None:
            out.append(name)
            continue
        try:
            __import__(mod)
            out.append(name)
        except Exception:  # noqa: BLE001 - a broken optional install counts as absent
            pass
    return out


def make_linear_solver(name: str = "auto"):
    """A linear solver by name; ``"auto"`` takes PARDISO if it loads (MKL found), else SciPy's
    SuperLU, with a warning since it is several times slower.
    """
    if name == "auto":
        try:
            return LINEAR_SOLVERS["pardiso"]()
        except (ImportError, OSError) as e:
            warnings.warn(
                f"PARDISO is not available ({e}); the FEM falls back to SciPy's "
                "SuperLU, several times slower",
                RuntimeWarning,
                stacklevel=2,
            )
            return LINEAR_SOLVERS["superlu"]()
    if name not in LINEAR_SOLVERS:
        raise ValueError(f"unknown linear solver {name!r}")
    try:
        return LINEAR_SOLVERS[name]()
    except (ImportError, OSError) as e:
        raise ImportError(
            f"linear solver {name!r} needs a package that is not installed: {e}"
        ) from e
