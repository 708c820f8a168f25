"""The envelope: contacts, a scene's features (closed forms), the check, widening by a test set,
and what predictors do outside it.
"""

import warnings

import numpy as np
import pytest

from stmpl import loads, predictor
from stmpl.envelope import Envelope, contacts, features
from stmpl.predictor import OutsideEnvelope, PredictionFailed
from stmpl.scene import Scene


def _two_disks(part, total=0.2):
    a = loads.disk(part, uv=(0.3, 0.5), radius=0.015, total=total / 2)
    b = loads.disk(part, uv=(0.7, 0.5), radius=0.015, total=total / 2)
    return a, b, loads.combine(part, a, b)


def test_contacts_are_the_connected_loaded_patches(ds):
    part = ds.part
    a, b, both = _two_disks(part)
    assert contacts(part, np.zeros(part.n_vertices)) == []
    one = contacts(part, a.force)
    assert len(one) == 1 and set(one[0]) == set(a.vertices)
    two = contacts(part, both.force)
    assert len(two) == 2
    assert sorted(map(len, two)) == sorted([a.count, b.count])
    from scipy.sparse.csgraph import connected_components

    rng = np.random.default_rng(0)  # any pattern: scipy's components
    for share in (0.05, 0.3, 0.6, 0.95):
        f = (rng.random(part.n_vertices) < share).astype(float)
        on = np.flatnonzero(f)
        n, label = connected_components(part.adjacency[on][:, on], directed=False)
        want = [on[label == c] for c in range(n)]
        got = contacts(part, f)
        assert len(got) == n > 0 and all(np.array_equal(x, y) for x, y in zip(got, want))


def test_features_are_force_over_area(ds):
    part = ds.part
    a, b, both = _two_disks(part, total=0.3)
    t = np.full(part.n_vertices, 0.006)
    f = features(part, t, both.force)
    assert f["contacts"] == 2 and f["thickness"] == pytest.approx([0.006, 0.006])
    assert sum(f["contact_force"]) == pytest.approx(0.3)
    assert sorted(f["contact_area"]) == pytest.approx(sorted([a.area, b.area]))
    for F, A, P in zip(f["contact_force"], f["contact_area"], f["contact_pressure"]):
        assert P == pytest.approx(F / A)
    assert f["peak_pressure"] == pytest.approx((both.force / part.vertex_areas).max())
    from stmpl.envelope import _around

    t2 = np.full(part.n_vertices, 0.012)  # reach 24 mm: past the next ring
    near = _around(part, a.vertices, 2 * 0.012)  # the tissue a's contact moves
    assert set(a.vertices) < set(near)
    far = np.setdiff1d(np.arange(part.n_vertices), near)
    t2[far] = 0.006  # thinner only beyond it: no matter
    assert features(part, t2, a.force)["thickness_variation"] == 0
    t2[near[~np.isin(near, a.vertices)][0]] = 0.009  # thinner beside the contact: counts
    mean = t2[near].mean()
    assert features(part, t2, a.force)["thickness_variation"] == pytest.approx(0.003 / mean)


@pytest.fixture
def env_ds(ds):
    """The envelope of the tiny dataset's training split."""
    a = ds.arrays("train")
    return Envelope.of(ds.part, a["thickness"], a["force"], source="tiny"), a


def test_training_scenes_are_inside_and_each_axis_is_named_when_left(ds, env_ds):
    env, a = env_ds
    part = ds.part
    for t, f in zip(a["thickness"], a["force"]):
        assert env.reasons(part=part, thickness=t, force=f) == []
    box = env.boxes["training"]
    assert box["thickness"] == pytest.approx([0.005, 0.010])
    assert box["contacts"] == [1, 1]
    k = int(np.argmax(a["total"]))  # the heaviest training scene
    t, f = a["thickness"][k], a["force"][k]

    def why(**kw):
        return " | ".join(env.reasons(part=part, **{"thickness": t, "force": f, **kw}))

    assert "mean pressure of a contact" in why(force=f * 20) and "force of a contact" in why(
        force=f * 20
    )
    assert "tissue thickness 2.5 mm < 5 mm" in why(thickness=np.full_like(t, 0.0025))
    assert "tissue thickness 12 mm > 10 mm" in why(thickness=np.full_like(t, 0.012))
    _, _, both = _two_disks(part, total=0.1)
    assert "number of contacts 2 > 1" in why(force=both.force)
    assert why(force=f * (1 + 0.5 * 0.02)) == ""  # within the slack
    assert why(force=f * 0.5) == ""  # lighter is never outside


def test_round_trip_and_corrupt_envelopes(env_ds):
    env, _ = env_ds
    back = Envelope.from_dict(env.to_dict())
    assert back.boxes == env.boxes and back.info == env.info
    d = env.to_dict()
    with pytest.raises(ValueError, match="not a stmpl envelope"):
        Envelope.from_dict({**d, "format": "x"})
    with pytest.raises(ValueError, match="unknown axis 'colour'"):
        Envelope.from_dict({**d, "boxes": {"training": {"colour": [0, 1]}}})
    with pytest.raises(ValueError, match="finite and rising"):
        Envelope.from_dict({**d, "boxes": {"training": {"contacts": [2, 1]}}})
    with pytest.raises(ValueError, match="at least one box"):
        Envelope.from_dict({**d, "boxes": {}})


def test_widen_takes_only_scenes_as_intense_as_training(ds, env_ds):
    env, a = env_ds
    part = ds.part
    t = np.full(part.n_vertices, 0.006)
    _, _, light = _two_disks(part, total=0.1)
    _, _, heavy = _two_disks(part, total=4.0)
    mask = env.widen("two", part, np.stack([t, t]), np.stack([light.force, heavy.force]))
    assert mask.tolist() == [True, False]
    assert env.boxes["two"]["contacts"] == [1, 2]
    assert env.boxes["two"]["contact_pressure"] == env.boxes["training"]["contact_pressure"]
    assert env.reasons(part=part, thickness=t, force=light.force) == []
    assert env.reasons(part=part, thickness=t, force=heavy.force) != []


def test_predictors_flag_warn_once_and_refuse_when_strict(ds, make, env_ds):
    env, a = env_ds
    p = make("gnn", ds)
    p.envelope = env
    k = int(np.argmax(a["total"]))
    inside = Scene(ds.part, a["thickness"][k], a["force"][k])
    outside = Scene(ds.part, a["thickness"][k], a["force"][k] * 20)
    with warnings.catch_warnings():  # an untrained network: only the envelope's verdict counts
        warnings.simplefilter("error", OutsideEnvelope)
        d = p.predict(inside)
    assert d.info["envelope"] == {"inside": True, "outside": []}
    with pytest.warns(OutsideEnvelope) as rec:
        ds_ = p.predict([inside, outside, outside])
    assert len([w for w in rec if w.category is OutsideEnvelope]) == 1
    assert "2 of 3 scenes lie outside" in str(rec[0].message)
    assert [x.info["envelope"]["inside"] for x in ds_] == [True, False, False]
    assert "mean pressure" in ds_[1].info["envelope"]["outside"][1]
    with pytest.raises(PredictionFailed, match="strict: refused"):
        p.predict(outside, strict=True)
    p.strict = True
    with pytest.raises(PredictionFailed):
        p.predict([inside, outside])
    assert p.predict(inside).info["envelope"]["inside"]
    assert predictor.create("fem").envelope is None


def test_training_records_the_envelope_and_the_checkpoint_keeps_it(tiny_dataset, tmp_path):
    from stmpl.pipeline.evaluate import evaluate_dataset
    from stmpl.pipeline.train import train

    cfg = {
        "name": "n",
        "model": "naive",
        "data": str(tiny_dataset),
        "out": str(tmp_path),
        "epochs": 1,
    }
    p = predictor.read(train(cfg, progress=False))
    assert p.envelope.boxes["training"]["thickness"] == pytest.approx([0.005, 0.010])
    from stmpl.data.dataset import Dataset

    ds = Dataset(tiny_dataset)
    assert p.envelope.info["training"]["scenes"] == ds.card["samples_per_split"]["train"]
    # measured on its validation split (never trained on): the evidence of where it keeps
    # the per-scene promise; this Naive keeps it nowhere, and says so on the test split
    kept = p.envelope.support.kept
    assert len(kept) == ds.card["samples_per_split"]["val"] and not kept.any()
    assert "validation split" in p.envelope.support.sources[0]["source"]
    r = evaluate_dataset(p, ds, "test")
    assert r["inside_envelope"][0] == pytest.approx(0.0) and r["inside_broken"] == 0


def test_a_contact_nearer_the_rims_than_any_in_training_is_outside(ds):
    """The rim distance is checked at its low end only: a training box built from loads in the
    middle of the tube refuses a load on its rim.
    """
    part = ds.part
    t = np.full(part.n_vertices, 0.006)
    mid = loads.disk(part, uv=(0.5, 0.5), radius=0.02, total=0.1)
    env = Envelope.of(part, t[None], mid.force[None])
    assert env.boxes["training"]["rim_distance"][0] > 0.03
    rim = np.zeros(part.n_vertices)
    rim[part.rims[0][:3]] = 0.1 / 3
    why = env.reasons(part=part, thickness=t, force=rim)
    assert any(
        w.startswith("distance of a contact from the part's open rims 0 mm <") for w in why
    ), why
    assert env.reasons(part=part, thickness=t, force=mid.force * 0.5) == []
