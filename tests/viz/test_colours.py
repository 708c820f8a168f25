"""Colour ramps (stmpl/viz/colours.py)."""

import numpy as np
import pytest

from stmpl.viz.colours import ramp


def test_ramps_run_from_their_first_colour_to_their_last_darkening():
    np.testing.assert_allclose(ramp("YlOrRd", 0.0), [1.0, 1.0, 0xCC / 255])
    np.testing.assert_allclose(ramp("YlOrRd", 1.0), [0x80 / 255, 0.0, 0x26 / 255])
    np.testing.assert_allclose(ramp("PuBu", 1.0), [0x02 / 255, 0x38 / 255, 0x58 / 255])
    # halfway between two of the nine colours: their mean
    np.testing.assert_allclose(ramp("PuBu", 1 / 16), (ramp("PuBu", 0) + ramp("PuBu", 1 / 8)) / 2)
    light = ramp("YlOrRd", np.linspace(0, 1, 50)).sum(1)
    assert (np.diff(light) <= 1e-12).all()
    np.testing.assert_allclose(ramp("YlOrRd", 1.7), ramp("YlOrRd", 1.0))  # beyond: the end
    assert ramp("PuBu", np.zeros((4, 5))).shape == (4, 5, 3)


def test_bad_ramps_and_values_are_named():
    with pytest.raises(ValueError, match="unknown colour ramp 'jet'"):
        ramp("jet", 0.5)
    with pytest.raises(ValueError, match="must be finite"):
        ramp("PuBu", [0.1, np.nan])
