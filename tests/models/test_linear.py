"""Precomputed linear FEM: the sparse operator applies the FEM's compliance, interpolates in
thickness, refuses what it does not cover and travels in its checkpoint.
"""

import numpy as np
import pytest
import torch

from models.linear.operator import ComplianceOperator
from stmpl import predictor
from stmpl.metrics import sample_metrics
from stmpl.pipeline.evaluate import scenes_of
from stmpl.scene import Scene


@pytest.fixture(scope="module")
def ds(tiny_dataset):
    from stmpl.data.dataset import Dataset

    return Dataset(tiny_dataset)


@pytest.fixture(scope="module")
def lin(ds):
    p = predictor.create("linear", ds.part)
    p.fit(ds, progress=False)
    return p


def _operator(rng, n=6, levels=(0.005, 0.01)):
    G = rng.normal(size=(len(levels), n, n, 3))
    op = ComplianceOperator()
    i, j = np.nonzero(np.ones((n, n)))
    op.set(levels, np.stack([i, j]), G[:, i, j])
    return op, G


def test_operator_is_the_dense_product_interpolated_in_thickness(rng):
    op, G = _operator(rng)
    f = rng.uniform(0, 1, (2, 6))
    t = np.stack([np.full(6, 0.005), np.full(6, 0.0075)])
    u = op(torch.tensor(t, dtype=torch.float32), torch.tensor(f, dtype=torch.float32)).numpy()
    np.testing.assert_allclose(u[0], np.einsum("ijc,j->ic", G[0], f[0]), rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(
        u[1], np.einsum("ijc,j->ic", (G[0] + G[1]) / 2, f[1]), rtol=1e-5, atol=1e-5
    )
    # per-vertex thickness: each loaded vertex's column at its own thickness
    tv = np.where(np.arange(6) < 3, 0.005, 0.01)
    Gm = np.where((np.arange(6) < 3)[None, :, None], G[0], G[1])
    u = op(
        torch.tensor(tv[None], dtype=torch.float32), torch.tensor(f[:1], dtype=torch.float32)
    ).numpy()[0]
    np.testing.assert_allclose(u, np.einsum("ijc,j->ic", Gm, f[0]), rtol=1e-5, atol=1e-5)
    with pytest.raises(ValueError, match=r"outside the operator's levels 5..10 mm"):
        op(torch.full((1, 6), 0.012), torch.ones(1, 6))
    # a new operator of the same shape replaces the cached sparse matrices
    op.set(op.levels, op.index, 2 * op.values)
    u2 = op(
        torch.tensor(tv[None], dtype=torch.float32), torch.tensor(f[:1], dtype=torch.float32)
    ).numpy()[0]
    np.testing.assert_allclose(u2, 2 * u, rtol=1e-5, atol=1e-5)


def test_linear_matches_light_fem_loads(ds, lin):
    """At the lightest level (0.05 N) the tissue is still linear: the operator (skin refined
    everywhere) is within a few per cent of the ground truth (refined near the load).
    """
    scenes, truth = scenes_of(ds, "train")
    light = [k for k, s in enumerate(scenes) if np.isclose(s.meta["total"], 0.05)]
    assert len(light) >= 8
    pred = lin.predict([scenes[k] for k in light])
    rel = [sample_metrics(truth[k], d.displacement)["rel_mee"] for d, k in zip(pred, light)]
    assert np.mean(rel) < 5.0  # per cent
    # and it overshoots as the Neo-Hookean layer stiffens under heavier loads
    heavy = [k for k, s in enumerate(scenes) if np.isclose(s.meta["total"], 0.2)]
    pk = [
        np.linalg.norm(lin.predict(scenes[k]).displacement, axis=1).max()
        / np.linalg.norm(truth[k], axis=1).max()
        for k in heavy
    ]
    assert np.median(pk) > 1.0


def test_checkpoint_carries_the_operator(ds, lin, tmp_path):
    path = lin.save(tmp_path / "lin.safetensors")
    back = predictor.read(path)
    assert back.n_parameters() == 0 and back.model.index.shape == lin.model.index.shape
    s = scenes_of(ds, "test", limit=2)[0]
    for a, b in zip(lin.predict(s), back.predict(s)):
        np.testing.assert_array_equal(a.displacement, b.displacement)


def test_thickness_outside_the_levels_is_refused(ds, lin):
    n = ds.part.n_vertices
    s = Scene(ds.part, np.full(n, 0.012), np.where(np.arange(n) == 40, 0.1, 0.0))
    with pytest.raises(ValueError, match="outside the operator's levels"):
        lin.predict(s)


def test_options_are_checked(ds):
    with pytest.raises(ValueError, match="levels_mm"):
        predictor.create("linear", ds.part, {"levels_mm": [-5]})
    with pytest.raises(ValueError, match="tol"):
        predictor.create("linear", ds.part, {"tol": 2})


def test_on_demand_operator_agrees_with_the_stored_one(ds, lin, tmp_path, monkeypatch):
    """``operator: on_demand`` solves only the columns the samples load, on patches, and gives
    the stored operator's answers; its checkpoint carries no operator and rebuilds it.
    """
    monkeypatch.setenv("STMPL_CACHE_DIR", str(tmp_path))
    lazy = predictor.create("linear", ds.part, {"operator": "on_demand"})
    lazy.fit(ds, progress=False)
    meta = lazy.meta["operator"]
    assert meta["mode"] == "on_demand" and 0 < meta["columns_at_fit"]
    scenes, truth = scenes_of(ds, "test", limit=6)
    for s, a, b in zip(scenes, lin.predict(scenes), lazy.predict(scenes)):
        peak = np.linalg.norm(a.displacement, axis=1).max()
        assert np.linalg.norm(a.displacement - b.displacement, axis=1).max() < 0.01 * peak
    path = lazy.save(tmp_path / "lazy.safetensors")
    assert path.stat().st_size < lin.save(tmp_path / "lin.safetensors").stat().st_size
    back = predictor.read(path)
    assert back.model.on_demand and back.model.store.computed == 0  # nothing solved yet
    for a, b in zip(lazy.predict(scenes), back.predict(scenes)):  # from the disk cache
        np.testing.assert_allclose(a.displacement, b.displacement, rtol=1e-6, atol=1e-12)
    with pytest.raises(ValueError, match="operator must be one of"):
        predictor.create("linear", ds.part, {"operator": "lazy"})


def test_on_demand_takes_a_new_thickness_as_a_new_level(ds, tmp_path, monkeypatch):
    """On demand, a thickness beyond the levels, thicker or thinner, is solved there (a new
    level, once), not refused, and agrees with an operator computed at that thickness from the
    start.
    """
    monkeypatch.setenv("STMPL_CACHE_DIR", str(tmp_path))
    lazy = predictor.create("linear", ds.part, {"operator": "on_demand"})
    lazy.fit(ds, progress=False)
    n = ds.part.n_vertices
    s = Scene(ds.part, np.full(n, 0.012), np.where(np.arange(n) == 40, 0.1, 0.0))
    u = lazy.predict(s).displacement
    assert 0.012 in np.round(lazy.model.levels.numpy().astype(float), 6)
    from fem.compliance import ColumnStore

    G = ColumnStore(ds.part, ds.card["config"], [0.012]).columns(0, [40])[:, 0]
    np.testing.assert_allclose(u, 0.1 * G, rtol=1e-5, atol=1e-12)
    thicker = lazy.predict(Scene(ds.part, np.full(n, 0.011), s.force)).displacement
    assert 0 < np.abs(thicker).max()  # between 10 and 12 mm: interpolated
    thinner = lazy.predict(Scene(ds.part, np.full(n, 0.004), s.force)).displacement
    assert np.isfinite(thinner).all() and 0 < np.abs(thinner).max() < np.abs(u).max()
    levels = lazy.model.levels.numpy()
    assert len(np.unique(levels)) == len(levels)  # each new thickness a level once


def test_a_prepared_body_answers_a_press_anywhere_without_solving(ds, tmp_path, monkeypatch):
    """``prepare`` solves every vertex's column at the levels a thickness needs, once (the disk
    cache then holds them): a press at any place afterwards solves nothing, and its answer is
    the one solved on demand.
    """
    monkeypatch.setenv("STMPL_CACHE_DIR", str(tmp_path))
    lazy = predictor.create("linear", ds.part, {"operator": "on_demand"})
    lazy.fit(ds, progress=False)
    n = ds.part.n_vertices
    t = np.full(n, 0.0075)  # between two levels: both are needed
    solved = lazy.prepare(ds.part, t, progress=False)
    store = lazy.model.store
    assert solved > 0 and all(store.missing(lv, np.arange(n)).size == 0 for lv in (0, 1))
    assert lazy.prepare(ds.part, t, progress=False) == 0  # once
    calls = len(store.log)
    places = [3, n // 2, n - 5]
    answers = [
        lazy.predict(Scene(ds.part, t, np.where(np.arange(n) == k, 0.1, 0.0))) for k in places
    ]
    assert len(store.log) == calls  # nothing solved at a press
    fresh = predictor.create("linear", ds.part, {"operator": "on_demand"})
    fresh.fit(ds, progress=False)
    monkeypatch.setenv("STMPL_CACHE_DIR", str(tmp_path / "cold"))  # solved on demand instead
    for k, a in zip(places, answers):
        s = Scene(ds.part, t, np.where(np.arange(n) == k, 0.1, 0.0))
        np.testing.assert_allclose(a.displacement, fresh.predict(s).displacement, atol=1e-12)
    with pytest.raises(ValueError, match="thickness must be"):
        lazy.prepare(ds.part, t[:-1], progress=False)


def test_a_layered_press_set_gets_the_linear_fem_of_its_own_tissue(
    tiny_presses, tmp_path, monkeypatch
):
    """Fitted on a set of the layered forearm preset, the on-demand operator is solved on that
    preset (its set-up names it) and answers each press's contact forces with the preset's
    columns, not the paper gel's (1 kPa throughout: a dent three times deeper).
    """
    from fem.compliance import local_compliance
    from stmpl.data.dataset import Dataset

    monkeypatch.setenv("STMPL_CACHE_DIR", str(tmp_path))
    ds = Dataset(tiny_presses)
    lin = predictor.create("linear", ds.part, {"operator": "on_demand"})
    lin.fit(ds, progress=False)
    setup = lin.meta["operator"]["setup"]
    assert setup["tissue"] == "forearm" and "phenotype" in setup
    (scene,), _ = scenes_of(ds, "test", limit=1)
    got = lin.predict(scene).displacement
    loaded = np.flatnonzero(scene.force > 0)
    t = float(scene.thickness[0])
    G, _ = local_compliance(ds.part, t, loaded, setup["resolution"], tissue="forearm")
    deepest = np.linalg.norm(got, axis=1).max()
    # the fit solved every sample's columns on one patch, this the test press's alone: the
    # same columns to the patches' cut (the stiff skin carries a dent far along a limb)
    direct = np.einsum("nkc,k->nc", G, scene.force[loaded])
    assert np.abs(got - direct).max() < 0.03 * deepest
    gel, _ = local_compliance(ds.part, t, loaded, setup["resolution"])
    assert np.linalg.norm(np.einsum("nkc,k->nc", gel, scene.force[loaded]), axis=1).max() > (
        2 * deepest
    )  # the gel: 4.8 mm where the forearm's layers give 1.4


@pytest.mark.filterwarnings("ignore::stmpl.failures.OutsideEnvelope")
def test_given_a_pose_it_answers_the_closure_and_its_contact_forces(
    tiny_presses, tmp_path, monkeypatch
):
    """Given a pose and its motion, the linear FEM answers the closure of the skin's compliance
    (:meth:`fem.holding.HeldSkin.closed`): where the object pushes, the skin lies on its
    surface (``u . n`` is the rest gap, the analytic ball and disk unrounded), the answered
    contact force is the closure's normal force there and nothing elsewhere, and the reaction
    is their sum. Its checkpoint gives the same answers; options it cannot honour are refused.
    """
    from stmpl.data.dataset import Dataset

    monkeypatch.setenv("STMPL_CACHE_DIR", str(tmp_path))
    ds = Dataset(tiny_presses)
    with pytest.raises(ValueError, match="it needs motion: true"):
        predictor.create("linear", ds.part, {"given": "pose"})
    with pytest.raises(ValueError, match="operator.*given a pose"):
        predictor.create(
            "linear", ds.part, {"given": "pose", "motion": True, "operator": "on_demand"}
        )
    lin = predictor.create("linear", ds.part, {"given": "pose", "motion": True})
    scenes, _ = scenes_of(ds, "test", given="pose", way=True)
    with pytest.raises(ValueError, match="the closure needs the skin's linear FEM"):
        lin.predict(scenes[0])
    lin.fit(ds, progress=False)
    assert lin.meta["holding"]["rounding_m"] == 0.0
    back = predictor.read(lin.save(tmp_path / "lin.safetensors"))
    for s, d, e in zip(scenes, lin.predict(scenes), back.predict(scenes)):
        _, f = lin.held_skin.closed(s.pose.gap, s.pose.way, s.thickness, 0.0, 0.0)
        normal = -np.einsum("ij,ij->i", f, s.part.normals)
        pushed = normal > 0
        assert pushed.any()
        np.testing.assert_allclose(d.force[pushed], normal[pushed], rtol=1e-12)
        assert (d.force[~pushed] == 0).all()
        assert d.reaction == pytest.approx(normal[pushed].sum(), rel=1e-12)
        inward = np.einsum("ij,ij->i", d.displacement, s.part.normals)
        deepest = -s.pose.gap.min()
        assert np.abs(inward[pushed] - s.pose.gap[pushed]).max() < 1e-3 * deepest
        np.testing.assert_array_equal(d.displacement, e.displacement)
        assert d.reaction == e.reaction
    assert lin.held_skin._closures  # kept for the next call with the same pose ...
    lin.forget_scenes()  # ... until forgotten: a timed call then pays a new pose's closure
    assert not lin.held_skin._closures
    again = lin.predict(scenes[0])
    np.testing.assert_array_equal(again.displacement, lin.predict(scenes[0]).displacement)
