import numpy as np
import pytest

from fem.material import (
    Demiray,
    Layered,
    LinearElastic,
    NeoHookean,
    Yeoh,
    lame,
    material,
    uniaxial,
)


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


LAWS = [
    NeoHookean(1000.0, 0.45),
    Yeoh(K=2e4, C10=400.0),
    Yeoh(K=2e4, C10=400.0, C20=2000.0, C30=500.0),
    Demiray(K=2e4, a=800.0, b=8.0),
]


@pytest.mark.parametrize("law", LAWS[1:], ids=lambda m: m.name)
def test_tissue_laws_stress_and_tangent_are_exact_derivatives(law):
    F = _random_F()
    P, A = law.stress_tangent(F)
    h = 1e-6
    for k in range(3):
        for L in range(3):
            dF = np.zeros((3, 3))
            dF[k, L] = h
            dW = (law.energy(F + dF) - law.energy(F - dF)) / (2 * h)
            np.testing.assert_allclose(dW, P[:, k, L], rtol=1e-6, atol=1e-6 * abs(P).max())
            dP = (law.stress(F + dF) - law.stress(F - dF)) / (2 * h)
            np.testing.assert_allclose(dP, A[:, :, :, k, L], rtol=1e-5, atol=1e-6 * abs(A).max())


@pytest.mark.parametrize("law", LAWS[1:], ids=lambda m: m.name)
def test_tissue_laws_are_linear_elastic_at_rest(law):
    """Stress-free at rest, with the small-strain tangent of (E, nu) from (mu, K)."""
    I = np.eye(3)[None]
    np.testing.assert_allclose(law.stress(I), 0.0, atol=1e-9)
    lin = LinearElastic(law.E, law.nu)
    np.testing.assert_allclose(law.stress_tangent(I)[1], lin.stress_tangent(I)[1], rtol=1e-9)
    assert law.mu == pytest.approx(800.0)
    assert 9 * law.K * law.mu / (3 * law.K + law.mu) == pytest.approx(law.E)


def test_stiffening_laws_stiffen_under_compression():
    """The secant modulus at 30 % compression over the initial one: 1.49 for the neo-Hookean
    shape part (its incompressible curve, mu (l - 1/l^2), gives (0.7 - 1/0.49) / -0.9), several
    times that for Yeoh with C20, C30 > 0 and for Demiray.
    """
    ratios = {}
    for law in LAWS[1:]:
        p, _ = uniaxial(law, 0.7)
        p0, _ = uniaxial(law, 0.999)
        ratios[law] = (p / -0.3) / (p0 / -0.001)
    nh, yeoh, demiray = ratios.values()
    assert nh == pytest.approx(1.49, abs=0.02) and yeoh > 3 * nh and demiray > 3 * nh


def test_layered_material_gives_each_element_its_layers_law():
    soft, stiff = Yeoh(K=2e4, C10=400.0), Yeoh(K=2e6, C10=4e4)
    mat = Layered((soft, stiff), np.array([1, 0, 1]))
    F = np.repeat(_random_F(3, 0.1), 2, axis=0)  # two quadrature points per element
    P = mat.stress(F)
    np.testing.assert_allclose(P[[0, 1, 4, 5]], stiff.stress(F[[0, 1, 4, 5]]))
    np.testing.assert_allclose(P[[2, 3]], soft.stress(F[[2, 3]]))
    assert mat.energy(F)[2] == pytest.approx(soft.energy(F[2:3])[0])


@pytest.mark.parametrize(
    "make, message",
    [
        (lambda: Yeoh(K=2e4, C10=-1.0), "C10 must be > 0"),
        (lambda: Yeoh(C10=400.0), "K must be > 0"),
        (lambda: Yeoh(K=2e4, C10=400.0, C20=-5.0), "C20 and C30 must be >= 0"),
        (lambda: Demiray(K=2e4, a=800.0, b=float("nan")), "b must be > 0"),
        (lambda: Layered((Yeoh(K=2e4, C10=4.0),), np.array([0, 1])), "indices into the 1 laws"),
    ],
)
def test_bad_law_parameters_are_named(make, message):
    with pytest.raises(ValueError, match=message):
        make()
