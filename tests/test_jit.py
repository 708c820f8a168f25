"""Numba's compiler where it is installed, and ``None`` (the NumPy ways) where it is not."""

import sys

import numpy as np

from stmpl.jit import loaded, njit


def _norms(x):
    out = np.empty(x.shape[0])
    for i in range(x.shape[0]):
        out[i] = np.sqrt(x[i, 0] ** 2 + x[i, 1] ** 2 + x[i, 2] ** 2)
    return out


def test_a_kernel_compiles_cached_and_without_the_gil():
    jit = njit(error_model="numpy")
    assert jit is not None, "numba is missing: the compiled kernels cannot be checked"
    assert loaded()
    kernel = jit(_norms)
    x = np.random.default_rng(0).normal(size=(50, 3))
    np.testing.assert_allclose(kernel(x), np.linalg.norm(x, axis=1), rtol=1e-14)
    options = kernel.targetoptions
    assert options["nogil"] and options["error_model"] == "numpy"
    assert kernel._cache.__class__.__name__ == "FunctionCache"  # kept on disk


def test_without_numba_there_is_no_compiler(monkeypatch):
    monkeypatch.setitem(sys.modules, "numba", None)  # ``import numba`` raises ImportError
    assert njit() is None and njit(parallel=True) is None
