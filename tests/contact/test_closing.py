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


def test_a_grip_made_before_is_read_back_without_anny(arm, tmp_path, monkeypatch):
    """The main job's grip: the first is set and kept, the second read back as it was, path
    and all (anny never runs); another placement is set afresh.
    """
    from stmpl.contact import closing

    monkeypatch.setenv("STMPL_CACHE_DIR", str(tmp_path))
    first = closing.cached_closing_grip(arm, {}, "R", along=0.45, kind="tripod")
    direct = closing_grip(arm, Hand(side="R"), along=0.45, kind="tripod")
    np.testing.assert_array_equal(first.vertices, direct.vertices)
    np.testing.assert_array_equal(first.path, direct.path)

    def no_anny(*args, **kwargs):
        raise AssertionError("anny ran for a grip that was kept")

    monkeypatch.setattr(closing, "Hand", no_anny)
    again = closing.cached_closing_grip(arm, {}, "R", along=0.45, kind="tripod")
    for a, b in [(again.vertices, first.vertices), (again.faces, first.faces)]:
        np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(again.path, first.path)
    assert again.name == first.name
    with pytest.raises(AssertionError, match="anny ran"):
        closing.cached_closing_grip(arm, {}, "R", along=0.6, kind="tripod")
    with pytest.raises(ValueError, match="grip must be one of"):
        closing.cached_closing_grip(arm, {}, "R", kind="fist")
