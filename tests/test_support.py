"""The joint support and the out-of-sample evidence of an envelope: combinations the data never
held, lighter loads, measured scenes that kept or broke the promise, and the round trip.
"""

import numpy as np
import pytest

from stmpl import loads
from stmpl.envelope import Envelope
from stmpl.support import COORDS, Support


def _scenes(part, cases, thickness=0.006):
    """``(S, N)`` thickness and force of disks ``(radius m, total N)`` at the middle of ``part``."""
    t = np.full((len(cases), part.n_vertices), thickness)
    f = np.stack([loads.disk(part, uv=(0.5, 0.5), radius=r, total=n).force for r, n in cases])
    return t, f


def test_a_combination_the_data_never_held_is_outside_though_each_value_is_inside(ds):
    part = ds.part
    # light loads on thin tissue, heavy ones on thick: the box admits a heavy load on thin
    light = [(0.02, n) for n in (0.05, 0.075, 0.1)]
    heavy = [(0.02, n) for n in (0.3, 0.4, 0.5)]
    t = np.vstack([_scenes(part, light, 0.005)[0], _scenes(part, heavy, 0.01)[0]])
    f = np.vstack([_scenes(part, light)[1], _scenes(part, heavy)[1]])
    env = Envelope.of(part, t, f)
    for a, b in zip(t, f):
        assert env.reasons(part=part, thickness=a, force=b) == []
    a, b = _scenes(part, [(0.02, 0.45)], 0.005)
    why = env.reasons(part=part, thickness=a[0], force=b[0])
    assert len(why) == 1 and why[0].startswith("no scene in the data combines"), why
    # lighter than a scene of the data, on the same area and tissue: no harder, inside
    a, b = _scenes(part, [(0.02, 0.2), (0.02, 0.02)], 0.01)
    assert all(env.reasons(part=part, thickness=x, force=y) == [] for x, y in zip(a, b))


def test_measured_scenes_decide_near_them_and_survive_the_round_trip(ds):
    part = ds.part
    cases = [(0.02, n) for n in np.linspace(0.05, 0.5, 10)]
    env = Envelope.of(part, *_scenes(part, cases))
    # measured out of sample: the promise kept up to 0.3 N, broken above
    heavy = [(0.02, n) for n in (0.1, 0.2, 0.3, 0.4, 0.5)]
    rel = np.array([0.4, 0.6, 1.2, 2.5, 3.0])
    peak = np.array([1.0, -2.0, 4.0, -12.0, 9.0])
    kept = env.measure(part, *_scenes(part, heavy), rel, peak, source="val")
    assert kept.tolist() == [True, True, True, False, False]
    t, f = _scenes(part, [(0.02, 0.15), (0.02, 0.45)])
    assert env.reasons(part=part, thickness=t[0], force=f[0]) == []
    why = env.reasons(part=part, thickness=t[1], force=f[1])
    assert why and "broke the promise" in why[0] and "relative MEE 3.00 %, peak +9.0 %" in why[0], (
        why
    )
    # 0.25 N lies between 0.2 N (errors 0.4 of the promise) and 0.3 N (0.8 of it): kept, but
    # with too little room for a scene nearby to be trusted
    t2, f2 = _scenes(part, [(0.02, 0.25)])
    why = env.reasons(part=part, thickness=t2[0], force=f2[0])
    assert why and "came near breaking the promise" in why[0] and "1.20 %" in why[0], why
    back = Envelope.from_dict(env.to_dict())
    assert back.support.promise == (1.5, 10.0)
    for a, b in zip(t, f):
        assert back.reasons(part=part, thickness=a, force=b) == env.reasons(
            part=part, thickness=a, force=b
        )
    assert back.support.sources == [{"source": "val", "scenes": 5}]


def test_evidence_judged_by_another_promise_is_refused():
    s = Support.of(np.random.default_rng(0).random((5, len(COORDS))))
    s.measure(np.zeros((1, len(COORDS))), [True], [[0.1, 1.0]], "val", promise=(1.5, 10.0))
    with pytest.raises(ValueError, match="judged by promise"):
        s.measure(np.zeros((1, len(COORDS))), [True], [[0.1, 1.0]], "test", promise=(3.0, 10.0))


def test_a_bad_support_is_named():
    good = Support.of(np.random.default_rng(0).random((5, len(COORDS)))).to_dict()
    with pytest.raises(ValueError, match="support needs"):
        Support.of(np.zeros((3, 2)))
    with pytest.raises(ValueError, match="must be finite"):
        Support.of(np.full((3, len(COORDS)), np.nan))
    with pytest.raises(ValueError, match="coordinates"):
        Support.from_dict({**good, "coords": ["force"]})
    with pytest.raises(ValueError, match="unreadable"):
        Support.from_dict({**good, "points": "many"})
    with pytest.raises(ValueError, match="mismatched evidence"):
        Support.from_dict({**good, "measured": [[0.0] * len(COORDS)], "kept": []})


def test_the_quick_nearest_check_decides_as_the_one_sided_distance():
    """An answer is backed where the one-sided distance to the nearest training scene is within
    reach; the nearest-neighbour tree (a Euclidean distance, never shorter) only shortcuts it:
    over random scenes, inside and outside alike, the verdict is the full distance's.
    """
    rng = np.random.default_rng(3)
    s = Support.of(rng.normal(size=(300, len(COORDS))))
    queries = rng.normal(scale=1.6, size=(400, len(COORDS))) * s.scale
    inside = [not s.reasons(q) for q in queries]
    truth = [s.distance(q) <= s.reach * (1 + 1e-9) for q in queries]
    assert inside == truth and 20 < sum(inside) < 380
