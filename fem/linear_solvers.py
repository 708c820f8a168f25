"""Sparse linear solvers for the Newton steps, one interface (``factor(K, confirm)``, ``solve(b)``,
``precondition(b)``: a solve as good as a preconditioner needs,
``upper``: whether it wants only the upper triangle; ``direct``: whether ``solve`` applies a
fixed factorisation, which can then precondition later tangents): MKL PARDISO (Cholesky,
fastest; ``pardiso_single`` factorises in single precision and refines its solves in double),
SciPy's SuperLU (always there) and AMG-preconditioned conjugate gradients. A
factorisation that meets a non-positive pivot raises :class:`IndefiniteTangent`; ``confirm``
(default): only once a double-precision factorisation has met one too.
"""

from __future__ import annotations

import ctypes
import glob
import os
import sys
import warnings

import numpy as np
from scipy.sparse.linalg import cg, splu

from fem.krylov import symmetric_matvec


class IndefiniteTangent(ArithmeticError):
    """The tangent is not positive definite (the layer buckles or snaps through)."""


class _SuperLU:
    """SciPy's SuperLU with a minimum-degree ordering on ``A^T + A`` (always available)."""

    name, upper, direct = "superlu", False, True

    def factor(self, K, confirm: bool = True):

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

    precondition = solve


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

    def factor(self, K, confirm: bool = True):
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

    def precondition(self, b):
        return _Pardiso.solve(self, b)


class _PardisoSingle(_Pardiso):
    """PARDISO's Cholesky factorisation in single precision (MKL's ``iparm[27] = 1``): about
    half the time and memory of the double one, its solve refined against the double tangent
    (iterative refinement: each step gains some three digits) to :data:`REFINED`. Where the
    refinement stalls (a tangent too ill-conditioned for single precision), or a pivot is not
    positive, the tangent is factorised again in double precision and solved as
    :class:`_Pardiso` does (which alone says a tangent is indefinite).
    """

    name = "pardiso_single"

    def __init__(self):
        super().__init__()
        self._iparm = np.zeros(64, dtype=np.int32)
        self._iparm[[0, 1, 27]] = 1, 2, 1  # own settings, METIS ordering, single precision
        self._pt = np.zeros(64, dtype=np.int64)  # MKL's handle of the single factorisation
        self._single = False
        self._analysed_single = None

    def __del__(self):
        try:
            if self._analysed_single is not None:
                self._call(-1, np.zeros((0, 1), np.float32))
        except Exception:  # noqa: BLE001 - interpreter shutdown
            pass
        super().__del__()

    def _call(self, phase: int, b: np.ndarray) -> np.ndarray:
        """MKL's ``pardiso`` on the kept tangent in single precision: ``x`` for ``b`` ``(n, k)``."""
        K = self._K
        x = np.zeros_like(b)
        error = ctypes.c_int32(0)
        int_p = ctypes.POINTER(ctypes.c_int32)

        def ref(v):
            return ctypes.byref(ctypes.c_int32(v))

        self._solver._mkl_pardiso(
            self._pt.ctypes.data_as(ctypes.POINTER(ctypes.c_int64)),
            ref(1),
            ref(1),
            ref(2),  # real symmetric positive definite
            ref(phase),
            ref(K.shape[0]),
            self._data.ctypes.data_as(ctypes.c_void_p),
            self._ia.ctypes.data_as(int_p),
            self._ja.ctypes.data_as(int_p),
            np.zeros(0, np.int32).ctypes.data_as(int_p),
            ref(b.shape[1]),
            self._iparm.ctypes.data_as(int_p),
            ref(0),
            b.ctypes.data_as(ctypes.c_void_p),
            x.ctypes.data_as(ctypes.c_void_p),
            ctypes.byref(error),
        )
        if error.value == -4:
            raise IndefiniteTangent("Cholesky factorisation met a non-positive pivot")
        if error.value != 0:
            raise RuntimeError(f"PARDISO (single precision) failed: error {error.value}")
        return x

    def factor(self, K, confirm: bool = True):
        """``confirm=False``: a non-positive pivot in single precision is taken at its word
        (where a modified tangent stands ready: a Newton step then costs one factorisation
        less, and at worst descends more slowly); else a double factorisation settles it.
        """
        K = K.tocsr()
        K.sort_indices()
        self._K, self._single = K, True
        self._data = K.data.astype(np.float32)
        self._ia = (K.indptr + 1).astype(np.int32)
        self._ja = (K.indices + 1).astype(np.int32)
        self._matvec = symmetric_matvec(K, self.upper)
        b = np.zeros((K.shape[0], 1), np.float32, order="F")
        if self._analysed_single != (K.shape, K.nnz):
            self._call(11, b)
            self._analysed_single = (K.shape, K.nnz)
        try:
            self._call(22, b)
        except IndefiniteTangent:  # single precision's word alone does not settle it
            self._single = False
            if not confirm:
                raise
            super().factor(K)

    def precondition(self, b):
        """The single factorisation's solve as it is (some three digits: ample for CG)."""
        if not self._single:
            return super().solve(b)
        x = self._call(33, np.asfortranarray(b.reshape(len(b), -1), dtype=np.float32))
        return x.astype(float).reshape(b.shape)

    def solve(self, b):
        if not self._single:
            return super().solve(b)
        rhs = b.reshape(len(b), -1)
        scale = np.linalg.norm(rhs, axis=0)
        x, r, last = None, rhs, np.inf
        for _ in range(REFINE_STEPS):
            step = self._call(33, np.asfortranarray(r, dtype=np.float32))
            if x is None:
                x = step.astype(float)
            else:
                x += step
            r = rhs - self._matvec(x)
            left = float(np.max(np.linalg.norm(r, axis=0) / np.maximum(scale, 1e-300)))
            if left <= REFINED:
                return x.reshape(b.shape)
            if not left < 0.5 * last:  # the refinement does not converge
                break
            last = left
        # too ill-conditioned for single precision: this tangent in double
        self._single = False
        super().factor(self._K)
        return super().solve(b)


REFINED = 1e-10
"""The relative residual a single-precision solve is refined to (a double one reaches some
1e-12 on these tangents)."""
REFINE_STEPS = 6
"""Refinement steps before a single-precision factorisation gives way to a double one."""


class _AMGCG:
    """Conjugate gradients preconditioned by smoothed-aggregation AMG (pyamg)."""

    name, upper, direct = "cg", False, False

    def factor(self, K, confirm: bool = True):
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

    precondition = solve


LINEAR_SOLVERS = {
    "pardiso": _Pardiso,
    "pardiso_single": _PardisoSingle,
    "superlu": _SuperLU,
    "cg": _AMGCG,
}


def available_linear_solvers() -> list[str]:
    """Names of the linear solvers that import on this machine, fastest first."""
    out = []
    solvers = (("pardiso_single", "pypardiso"), ("pardiso", "pypardiso"), ("superlu", None))
    for name, mod in (*solvers, ("cg", "pyamg")):
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
    """A linear solver by name; ``"auto"`` takes PARDISO in single precision (its solves
    refined in double) if it loads (MKL found), else SciPy's SuperLU, with a warning since it
    is several times slower.
    """
    if name == "auto":
        try:
            return LINEAR_SOLVERS["pardiso_single"]()
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
