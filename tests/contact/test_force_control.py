"""Force control over a predictor that answers a pose: a stand-in whose reaction is a known
function of how deep its object reaches, so the depth found can be checked exactly; a force the
answers never reach, and a reaction that jumps across the force, refused by name.
"""

import numpy as np
import pytest

from stmpl import tissue
from stmpl.body import tube
from stmpl.contact import objects
from stmpl.contact.force_control import REACH, ForceNotMet, to_force
from stmpl.contact.posing import moved, posed
from stmpl.predictor import BasePredictor


class Hertzian(BasePredictor):
    """Answers a reaction ``k depth^1.5`` (N, depth in m: how deep the object reaches into the
    rest skin), at most ``most`` N; ``jump``: the reaction steps from 1 to 10 N there.
    """

    name, takes = "hertzian", ("pose",)

    def __init__(self, k=2e4, most=np.inf, jump=None):
        self.k, self.most, self.jump, self.asked = k, most, jump, 0
        self.dent = False  # answer the skin pushed in as deep as the object reaches
        self.forgot = None  # answers asked when it was last told to forget its scenes

    def forget_scenes(self):
        self.forgot = self.asked

    def reaction(self, depth):
        if self.jump is not None:
            return 1.0 if depth < self.jump else 10.0
        return min(self.k * depth**1.5, self.most)

    def predict_batch(self, scenes):
        self.asked += len(scenes)
        out = []
        for s in scenes:
            n, r = s.part.n_vertices, self.reaction(s.pose.depth)
            force = np.zeros(n)
            force[np.argmin(s.pose.gap)] = r
            u = np.zeros((n, 3))
            if self.dent:
                u = -np.maximum(-s.pose.gap, 0.0)[:, None] * s.part.normals
            out.append({"displacement": u, "force": force, "reaction": r})
        return out


@pytest.fixture(scope="module")
def start():
    part = tube(radius=0.04, length=0.12, n_around=32, n_along=16)
    tip = objects.sphere(0.008)
    pose = objects.press(part, tip, uv=(0.5, 0.5), depth=0.0)
    return posed(part, tissue.constant(part, 0.0075), tip, pose, name="fingertip")


@pytest.mark.parametrize("force", [0.2, 1.0, 5.0])
def test_the_object_is_pressed_to_the_depth_whose_reaction_is_the_force(start, force):
    p = Hertzian()
    a = to_force(p, start, force, rtol=1e-3)
    assert a.reaction == pytest.approx(force, rel=1e-3)
    assert a.scene.pose.depth == pytest.approx((force / p.k) ** (2 / 3), rel=2e-3)
    fc = a.info["force_control"]
    assert fc["force"] == force and fc["reaction"] == a.reaction
    again = moved(start, 1e-3 * fc["moved_mm"])  # the answer's scene: the start moved that far
    np.testing.assert_allclose(again.pose.gap, a.scene.pose.gap, atol=1e-12)
    assert fc["answers"] == p.asked <= 20
    assert p.forgot == p.asked - 1  # the answer returned is timed as a new scene's


def test_a_pose_already_past_the_force_is_moved_back(start):
    deep = moved(start, 0.004)
    a = to_force(Hertzian(), deep, 0.5, rtol=1e-3)
    assert a.info["force_control"]["moved_mm"] < 0
    assert a.reaction == pytest.approx(0.5, rel=1e-3)


def test_a_force_the_answers_never_reach_is_refused_by_name(start):
    with pytest.raises(
        ForceNotMet, match=r"reaches only 2 N .* 5 N is not met within 30 mm of travel"
    ):
        to_force(Hertzian(most=2.0), start, 5.0)
    assert REACH == 0.03


def test_a_force_met_only_past_the_tissue_s_bound_is_refused(start):
    """A model that answers an impossible dent (here past the gel's bound) before its
    reaction reaches the force is not searched deeper: refused, naming why.
    """
    p = Hertzian(k=2e3)
    p.dent = True
    with pytest.raises(ForceNotMet, match=r"no longer possible \(the skin moves inward"):
        to_force(p, start, 5.0)


def test_a_reaction_that_jumps_across_the_force_is_refused(start):
    with pytest.raises(ForceNotMet, match="jumps from 1 to 10 N across 5 N"):
        to_force(Hertzian(jump=0.002), start, 5.0)


def test_bad_requests_are_refused_in_one_line(start):
    with pytest.raises(ValueError, match="above 0 N, got nan"):
        to_force(Hertzian(), start, float("nan"))
    with pytest.raises(ValueError, match="above 0 N, got -1"):
        to_force(Hertzian(), start, -1.0)
    with pytest.raises(ValueError, match="rtol must lie in"):
        to_force(Hertzian(), start, 1.0, rtol=0.0)
