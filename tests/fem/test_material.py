import numpy as np
import pytest

from fem.material import LinearElastic, NeoHookean, lame, material


def _random_F(n=5, scale=0.2, seed=0):
    rng = np.random.default_rng(seed)
    return np.eye(3) + scale * rng.normal(size=(n, 3, 3))


@pytest.mark.parametrize("mat", [NeoHookean(1000.0, 0.4), LinearElastic(1000.0, 0.4)])
def test_stress_is_energy_gradient_and_tangent_is_stress_gradient(mat):
    F = _random_F()
    P, A = mat.stress_tangent(F)
    h = 1e-6
    for k in range(3):
        for L in range(3):
            dF = np.zeros((3, 3))
            dF[k, L] = h
            dW = (mat.energy(F + dF) - mat.energy(F - dF)) / (2 * h)
            np.testing.assert_allclose(dW, P[:, k, L], rtol=1e-6, atol=1e-6)
            dP = (mat.stress(F + dF) - mat.stress(F - dF)) / (2 * h)
            np.testing.assert_allclose(dP, A[:, :, :, k, L], rtol=1e-6, atol=1e-5)


def test_neo_hookean_matches_linear_elasticity_at_rest():
    nh, le = NeoHookean(2500.0, 0.3), LinearElastic(2500.0, 0.3)
    I = np.eye(3)[None]
    np.testing.assert_allclose(nh.stress(I), 0.0, atol=1e-12)
    np.testing.assert_allclose(nh.stress_tangent(I)[1], le.stress_tangent(I)[1], atol=1e-9)
    assert nh.energy(I)[0] == pytest.approx(0.0, abs=1e-12)
    # small strain: stresses agree to first order
    F = _random_F(scale=1e-5)
    np.testing.assert_allclose(nh.stress(F), le.stress(F), rtol=0, atol=2500 * 1e-8)


def test_uniaxial_stretch_closed_form():
    mat = NeoHookean(1000.0, 0.4)
    mu, lam = lame(1000.0, 0.4)
    s = 1.3
    F = np.diag([s, 1.0, 1.0])[None]
    P = mat.stress(F)[0]
    assert P[0, 0] == pytest.approx(mu * (s - 1 / s) + lam * np.log(s) / s)
    assert P[1, 1] == pytest.approx(lam * np.log(s))
    assert mat.energy(np.diag([1.0, 1.0, -1.0])[None])[0] == np.inf


def test_lame_and_bad_parameters():
    mu, lam = lame(1000.0, 0.4)
    assert mu == pytest.approx(1000 / 2.8) and lam == pytest.approx(400 / (1.4 * 0.2))
    with pytest.raises(ValueError, match="Poisson"):
        NeoHookean(1000.0, 0.5)
    with pytest.raises(ValueError, match="Young"):
        LinearElastic(-1.0, 0.3)
    with pytest.raises(ValueError, match="unknown material"):
        material("rubber")
    assert isinstance(material("linear", 10.0, 0.2), LinearElastic)
