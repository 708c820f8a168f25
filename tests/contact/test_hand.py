"""Hand grasps with anny's own hand (stmpl/contact/hand.py): the hand's fingers move one by one,
a grasp presses each finger of its grip the asked depth into the skin, and bad requests are named.
"""

import numpy as np
import pytest

import stmpl.contact.pressing as C
from stmpl.body import sheet, tube
from stmpl.contact import hand as hand_module
from stmpl.contact.hand import FINGERS, Hand, SkinDistance, cached_grasp, grasp


@pytest.fixture(scope="module")
def hand():
    return Hand()


def test_skin_distance_of_a_tube():
    t = tube(0.04, 0.2, 48, 40)
    skin = SkinDistance(t)
    x = np.array([[0.043, 0.0, 0.1], [0.0, 0.037, 0.12], [-0.05, 0.0, 0.05]])
    # a 48-gon's chords lie within 0.09 mm of the circle
    np.testing.assert_allclose(skin(x), [0.003, -0.003, 0.01], atol=2e-4)


def test_each_curl_moves_its_own_finger(hand):
    rest = hand.vertices({})
    np.testing.assert_allclose(rest, hand.rest, atol=1e-12)
    bent = hand.vertices({"index": 0.8})
    moved = np.linalg.norm(bent - rest, axis=1)
    assert np.mean(moved[hand.finger_of["index"]] > 0.005) > 0.8  # the index bends
    for f in ("thumb", "middle", "ring", "little"):  # the others stay (but the skin between)
        assert np.median(moved[hand.finger_of[f]]) < 1e-4 and moved[hand.finger_of[f]].max() < 0.01
    c, R = hand.frame()
    tip = hand.finger_of["middle"][np.argmax((rest[hand.finger_of["middle"]] - c) @ R[:, 0])]
    fist = hand.vertices({"middle": 1.0})
    # a fist brings the fingertip back to the palm (it ends on the palm's side of the hand)
    assert np.linalg.norm(fist[tip] - c) < np.linalg.norm(rest[tip] - c) - 0.03
    assert (fist[tip] - c) @ R[:, 1] > -0.01
    assert sum(len(v) for v in hand.finger_of.values()) == len(
        np.unique(np.concatenate(list(hand.finger_of.values())))
    )  # fingers are disjoint


@pytest.mark.parametrize(
    "call,message",
    [
        (lambda h, a: h.vertices({"pinky": 0.3}), "unknown finger 'pinky'"),
        (lambda h, a: h.vertices({"index": 2.0}), "curl of index must lie in"),
        (lambda h, a: grasp(a, h, grip="fist"), "grip must be one of"),
        (lambda h, a: grasp(a, h, depth=0.02), "depth must lie in"),
        (lambda h, a: grasp(a, h, along=1.5), "along must lie in"),
        (lambda h, a: grasp(sheet(), h), "no limb axis"),
    ],
)
def test_bad_requests_are_named(hand, arm, call, message):
    with pytest.raises(ValueError, match=message):
        call(hand, arm)


def test_a_whole_hand_grasp_presses_every_finger_and_the_palm(hand, arm):
    g = grasp(arm, hand, along=0.7, around=0.0, grip="whole", depth=0.002)
    assert set(g.reached) == set(FINGERS)
    skin = SkinDistance(arm)
    d = skin(g.vertices)
    for f in FINGERS:
        assert -d[hand.finger_of[f]].min() == pytest.approx(0.002, abs=5e-4), f
    assert -d[hand.palm].min() == pytest.approx(0.002, abs=2e-4)
    touch = C.contact(arm, g.pressing(0.4))
    assert len(touch.vertices) >= 3 and touch.force.sum() == pytest.approx(0.4)
    assert touch.open_objects == ("hand",)  # cut off at the wrist


def test_a_pinch_touches_with_thumb_and_index_only(hand, arm):
    g = grasp(arm, hand, along=0.5, around=0.5, grip="pinch", depth=0.002)
    skin = SkinDistance(arm)
    d = skin(g.vertices)
    assert set(g.reached) <= {"thumb", "index"} and "index" in g.reached
    assert d[hand.palm].min() > 0.01  # the palm stays off the skin
    for f in ("middle", "ring", "little"):
        assert g.curls[f] == 1.0 and d[hand.finger_of[f]].min() > 0


def test_an_open_hand_lies_on_a_belly(hand, anny_body):
    """On a part with no limb axis the open hand is laid on the skin: its deepest point over the
    skin lies the asked depth deep, the palm and the fingers touch, and fingers hanging past the
    part's rim do not hold it up.
    """
    from stmpl.contact.hand import palm_press

    belly = anny_body.part("belly")
    p = palm_press(belly, hand, (0.45, 0.5), 0.004, np.pi / 2, 0.4)
    world = p.posed().vertices
    s, over = SkinDistance(belly).over(world)
    assert -s[over].min() == pytest.approx(0.004, abs=1e-4)
    touch = C.contact(belly, p)
    assert len(touch.vertices) >= 8 and touch.force.sum() == pytest.approx(0.4)
    deep = np.flatnonzero(over & (s < -0.001))  # the hand's points in the skin
    assert len(set(hand.palm) & set(deep)) > 0 and len(set(hand.finger_of["middle"]) & set(deep))
    with pytest.raises(ValueError, match="depth must lie in"):
        palm_press(belly, hand, depth=0.02)


def test_a_grasp_made_before_is_read_back_without_anny(hand, arm, tmp_path, monkeypatch):
    """The main job's hand: the first grasp is posed and kept, the second read back as it was
    (anny never runs); another placement is posed afresh.
    """
    monkeypatch.setenv("STMPL_CACHE_DIR", str(tmp_path))
    first = cached_grasp(arm, {}, along=0.5, around=0.5, grip="pinch", depth=0.002)
    direct = grasp(arm, hand, along=0.5, around=0.5, grip="pinch", depth=0.002)
    np.testing.assert_array_equal(first.vertices, direct.vertices)

    def no_anny(*args, **kwargs):
        raise AssertionError("anny ran for a grasp that was kept")

    monkeypatch.setattr(hand_module, "Hand", no_anny)
    again = cached_grasp(arm, {}, along=0.5, around=0.5, grip="pinch", depth=0.002)
    np.testing.assert_array_equal(again.vertices, first.vertices)
    np.testing.assert_array_equal(again.faces, first.faces)
    assert again.curls == first.curls and again.reached == first.reached
    with pytest.raises(AssertionError, match="anny ran"):
        cached_grasp(arm, {}, along=0.6, around=0.5, grip="pinch", depth=0.002)
