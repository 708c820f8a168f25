"""The products of a compliance's columns (fem/columns.py): in float32, compiled as NumPy
gathers them; from the 16-bit copy within the bound its rounding sets, compiled and in NumPy;
columns made again once forgotten; bad input refused.
"""

import numpy as np
import pytest

from fem.columns import STEPS, Quantized, product


def _compliance(n: int = 300, seed: int = 0) -> np.ndarray:
    """A float32 matrix kept column by column, its columns' sizes spread over four decades."""
    rng = np.random.default_rng(seed)
    G = rng.normal(size=(n, n)) * 10.0 ** rng.uniform(-7, -3, n)
    return np.asfortranarray(G.astype(np.float32))


def test_the_float32_product_reads_the_columns_in_place_as_numpy_gathers_them(monkeypatch):
    """``G[:, at] @ f`` of a compliance kept column by column: compiled where Numba is loaded
    (the columns read in place, summed in float32 a few at a time and in float64 across
    them), NumPy's gather otherwise; the two agree to float32's rounding.
    """
    import stmpl.jit

    rng = np.random.default_rng(0)
    G = np.asfortranarray(rng.normal(size=(300, 300)).astype(np.float32))
    at = np.sort(rng.choice(300, 60, replace=False))
    f = rng.normal(size=60).astype(np.float32)
    exact = G[:, at].astype(np.float64) @ f.astype(np.float64)
    monkeypatch.setattr(stmpl.jit, "loaded", lambda: False)
    plain = product(G, at, f)
    monkeypatch.setattr(stmpl.jit, "loaded", lambda: True)
    fast = product(G, at, f)
    assert plain.dtype == fast.dtype == np.float32 and fast.shape == (300,)
    scale = np.abs(exact).max()
    np.testing.assert_allclose(fast, exact, rtol=0, atol=1e-6 * scale)
    np.testing.assert_allclose(plain, exact, rtol=0, atol=1e-5 * scale)


@pytest.mark.parametrize("compiled", [False, True])
def test_the_16_bit_product_lies_within_half_a_step_of_each_column(monkeypatch, compiled):
    """``G[:, at] @ f`` from the 16-bit columns: each entry within half its column's step
    (its largest entry over 32767), so the product within ``sum_j |f_j| s_j / 2`` (and
    float32's rounding) of the exact one, compiled as in NumPy.
    """
    import stmpl.jit

    monkeypatch.setattr(stmpl.jit, "loaded", lambda: compiled)
    G = _compliance()
    rng = np.random.default_rng(1)
    at = np.sort(rng.choice(300, 60, replace=False))
    f = rng.normal(size=60)
    q = Quantized(G)
    got = q.product(at, f)
    exact = G[:, at].astype(np.float64) @ f
    step = np.abs(G[:, at]).max(0) / STEPS
    bound = 0.5 * (np.abs(f) * step).sum() + 1e-6 * np.abs(exact).max()
    assert got.dtype == np.float32 and got.shape == (300,)
    assert (np.abs(got - exact) <= bound).all()
    assert np.abs(got - exact).max() > 0  # 16 bits, not the float32 columns
    assert q.have[at].all() and q.have.sum() == 60


def test_a_forgotten_column_is_made_again_from_the_matrix():
    G = _compliance(50)
    q = Quantized(G)
    at = np.array([3, 7])
    before = q.product(at, np.ones(2))
    G[:, 7] *= 2.0
    np.testing.assert_array_equal(q.product(at, np.ones(2)), before)  # kept as it was read
    q.forget([7])
    exact = G[:, at].astype(np.float64).sum(1)
    np.testing.assert_allclose(q.product(at, np.ones(2)), exact, atol=1e-4 * np.abs(exact).max())


def test_bad_input_is_refused():
    with pytest.raises(ValueError, match="float32 matrix kept column by column"):
        Quantized(np.zeros((4, 4)))
    with pytest.raises(ValueError, match="float32 matrix kept column by column"):
        Quantized(np.zeros((4, 4), np.float32))  # C order
    G = _compliance(20)
    q = Quantized(G)
    with pytest.raises(ValueError, match=r"f must be \(k,\)"):
        q.product([1, 2], np.ones(3))
    G[5, 4] = np.nan
    with pytest.raises(ValueError, match="not finite"):
        q.product([4], np.ones(1))
