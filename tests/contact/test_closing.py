"""anny's hand closing on a limb: every finger of the grip goes deeper as the grip closes."""

import numpy as np
import pytest

from stmpl.contact.closing import closed, closing_grip
from stmpl.contact.grips import GRIPS
from stmpl.contact.hand import Hand, SkinDistance


def test_every_finger_of_a_tripod_grip_closes_into_the_limb(arm):
    """Anny's tripod on her left arm: its middle finger cannot curl more than 4 mm into the
    forearm, so the path is drawn to that depth, and along it each of the three fingers goes
    steadily deeper (a path drawn to 8 mm drew the middle finger back out from 3 mm on).
    """
    hand = Hand(side="R")
    grip = closing_grip(arm, hand, along=0.45, kind="tripod")
    skin = SkinDistance(arm)
    depths = np.array(
        [
            [skin(closed(grip, d).vertices[hand.finger_of[f]]).min() for f in GRIPS["tripod"]]
            for d in np.arange(0.0, 0.0065, 0.0005)
        ]
    )
    assert depths[0].min() >= 0 and depths[-1].max() < -0.004
    assert (np.diff(depths, axis=0) < 0).all(), depths
    with pytest.raises(ValueError, match="no path to close along"):
        closed(closed(grip, 0.0).__class__("box", grip.vertices, grip.faces), 0.001)
