import numpy as np
import pytest

from stmpl import tissue
from stmpl.body import tube


@pytest.fixture(scope="module")
def part():
    return tube(n_around=16, n_along=11)


def test_paper_heuristics(part):
    assert tissue.from_weight(part, 0.0)[0] == pytest.approx(0.005)
    assert tissue.from_weight(part, 1.0)[0] == pytest.approx(0.010)
    levels = [tissue.from_weight(part, w)[0] for w in (0, 0.25, 0.5, 0.75, 1)]
    np.testing.assert_allclose(levels, tissue.LEVELS)
    np.testing.assert_allclose(
        [tissue.from_beta2(part, b)[0] for b in (-2, -1, 0, 1, 2)], tissue.LEVELS
    )


def test_smooth_maps(part):
    r = tissue.ramp(part, 0.004, 0.011)
    z = part.vertices[:, 2]
    np.testing.assert_allclose(r, 0.004 + 0.007 * z / z.max())
    b = tissue.bumps(part, 0.0075, 0.002, seed=1)
    assert b.std() > 0 and np.all(np.abs(b - 0.0075) <= 0.002 * 4)
    np.testing.assert_allclose(tissue.smooth(part, np.full(part.n_vertices, 0.006)), 0.006)
    rough = tissue.bumps(part, 0.0075, 0.002, length=0.005, seed=2)
    assert tissue.smooth(part, rough).std() < rough.std()


def test_normalisation_round_trip():
    t = np.array([0.0025, 0.0075, 0.0125])
    np.testing.assert_allclose(tissue.normalise(t), [0, 0.5, 1])
    np.testing.assert_allclose(tissue.denormalise(tissue.normalise(t)), t)


@pytest.mark.parametrize(
    "value,message",
    [
        (0.0, "must lie in"),
        (-0.001, "must lie in"),
        (0.02, "must lie in"),
        (np.nan, "not finite"),
    ],
)
def test_out_of_range_thickness_is_refused(part, value, message):
    with pytest.raises(ValueError, match=message):
        tissue.constant(part, value)


def test_a_bound_stored_in_single_precision_is_inside_and_a_micron_past_it_is_not(part):
    """A dataset stores thickness in float32, where 12.5 mm reads 12.5000002 mm: still the
    range's top, not past it; a thousandth of a millimetre past it is refused.
    """
    for bound in tissue.THICKNESS_RANGE:
        stored = np.full(part.n_vertices, np.float32(bound))
        np.testing.assert_array_equal(tissue.check(part, stored), stored.astype(float))
    with pytest.raises(ValueError, match="must lie in"):
        tissue.constant(part, tissue.THICKNESS_RANGE[1] + 1e-6)
    with pytest.raises(ValueError, match="must lie in"):
        tissue.constant(part, tissue.THICKNESS_RANGE[0] - 1e-6)


def test_bad_heuristic_inputs(part):
    with pytest.raises(ValueError, match="weight phenotype"):
        tissue.from_weight(part, 1.2)
    with pytest.raises(ValueError, match="beta_2"):
        tissue.from_beta2(part, 3)
    with pytest.raises(ValueError, match="shape"):
        tissue.check(part, np.full(3, 0.005))
