"""Evaluation on a dataset split: the seam measures, sample limits, the tables it writes."""

import numpy as np
import pytest


def test_evaluate_reports_seam_measures(ds, make):
    from stmpl.metrics import sample_metrics
    from stmpl.pipeline.evaluate import evaluate_dataset

    unet = evaluate_dataset(make("uv_unet", ds), ds, "test", limit=4)
    gnn = evaluate_dataset(make("gnn", ds), ds, "test", limit=4)
    assert unet["seam_gap"][0] > 0 and gnn["seam_gap"] == [0.0, 0.0]
    assert np.isfinite(unet["seam_mee"][0]) and np.isfinite(gnn["seam_mee"][0])
    # seam MEE is the MEE restricted to the seam's active vertices
    true = np.zeros((4, 3))
    true[:, 2] = 1e-3
    pred = true.copy()
    pred[1, 2] += 2e-3
    m = sample_metrics(true, pred, seam=np.array([1, 3]))
    assert m["seam_mee"] == pytest.approx(1.0) and m["mee"] == pytest.approx(0.5)


def test_limits_and_tables(ds, make, tmp_path):
    from stmpl.pipeline.evaluate import evaluate, scenes_of

    for bad in (0, -1, 2.5, True):
        with pytest.raises(ValueError, match="limit must be a number of samples >= 1"):
            scenes_of(ds, "test", limit=bad)
    scenes, truth = scenes_of(ds, "test", limit=3)
    assert len(scenes) == 3 and truth.shape == (3, ds.part.n_vertices, 3)
    md = evaluate({"naive": make("naive", ds)}, ds, "test", out=tmp_path / "t.md", limit=3)
    assert "| naive | 3 |" in md
    assert (tmp_path / "t.md").read_text().startswith(f"Dataset {ds.folder}")
    assert (tmp_path / "t.csv").read_text().splitlines()[1].startswith("naive,3,")


def test_a_scene_the_fem_fails_on_is_counted_and_left_out(ds, make):
    """The FEM answers scene by scene; one that fails is counted with its reason, not averaged
    in and not the end of the evaluation; failing on every scene is an error.
    """
    from stmpl.pipeline.evaluate import evaluate_dataset
    from stmpl.predictor import PredictionFailed

    fem = make("fem", ds)
    solve = fem.predict_batch
    seen = []

    def flaky(scenes):
        seen.append(len(scenes))
        if len(seen) == 2:
            raise PredictionFailed("the FEM solve failed at 0.2 N: indefinite tangent")
        return solve(scenes)

    fem.predict_batch = flaky
    res = evaluate_dataset(fem, ds, "test", limit=3)
    assert seen == [1, 1, 1] and res["samples"] == 2 and res["failed"] == 1
    assert "indefinite tangent" in res["failed_first"]

    def broken(scenes):
        raise PredictionFailed("the FEM cannot build the tissue")

    fem.predict_batch = broken
    with pytest.raises(PredictionFailed, match="failed on all 2 scenes"):
        evaluate_dataset(fem, ds, "test", limit=2)


def test_scenes_the_fem_did_not_solve_are_counted_with_the_answers_given_on_them(
    tiny_config, tmp_path, make
):
    """A planned sample the FEM could not solve (here: loads past the set's max_pressure) is
    never dropped: the evaluation counts it with its reason and judges the predictor's answer on
    it, flagged (outside its envelope, or impossible) or silent; an answer said inside that
    breaks the per-scene promise is counted too.
    """
    from fem.generate import generate
    from stmpl.data.dataset import Dataset
    from stmpl.envelope import Envelope
    from stmpl.pipeline.evaluate import evaluate_dataset

    cfg = tiny_config(
        thickness_mm=[5.0],
        forces=[0.05, 0.1, 2.0],
        max_pressure=1000.0,
        placements={"disk": {"centres": 5, "radii": [0.02]}},
    )
    card = generate(cfg, tmp_path / "d", progress=False)
    ds = Dataset(tmp_path / "d")
    n_test = card["failures_per_split"]["test"]
    assert n_test >= 1
    naive = make("naive", ds)
    train = ds.arrays("train")
    naive.envelope = Envelope.of(ds.part, train["thickness"], train["force"])
    res = evaluate_dataset(naive, ds, "test")
    assert res["unsolved"] == n_test
    assert res["unsolved_why"] == {"over max_pressure": n_test}
    # 2 N is 20x the training's heaviest load: every such answer is flagged
    assert res["unsolved_flagged"] == n_test and res["unsolved_silent"] == 0
    assert 0 <= res["inside_broken"] <= res["samples"]
    # without an envelope, an answer that looks possible is silent
    naive.envelope = None
    res = evaluate_dataset(naive, ds, "test")
    physical = [d.info["physical"] for d in naive.predict(_unsolved_scenes(ds))]
    assert res["unsolved_silent"] == sum(physical) and np.isnan(res["inside_broken"])
    # the FEM is not asked again where it failed
    assert evaluate_dataset(make("fem", ds), ds, "test", limit=1)["unsolved"] == n_test
    assert "unsolved_silent" not in evaluate_dataset(make("fem", ds), ds, "test", limit=1)


def _unsolved_scenes(ds):
    from stmpl.scene import Scene

    f = ds.failed("test")
    return [
        Scene(ds.part, t.astype(float), x.astype(float)) for t, x in zip(f["thickness"], f["force"])
    ]


class _Hertzian:
    """A stand-in pose model whose reaction rises as ``depth^1.5`` through ``(depth, reaction)``
    (m, N): where the FEM's sample lies. Its dent is the rest skin (zero).
    """

    from stmpl.predictor import BasePredictor as _Base

    class Model(_Base):
        name, takes = "hertzian", ("pose",)

        def __init__(self, depth, reaction, most=np.inf):
            self.depth, self.reaction, self.most = depth, reaction, most

        def predict_batch(self, scenes):
            out = []
            for s in scenes:
                n = s.part.n_vertices
                r = min(self.reaction * (s.pose.depth / self.depth) ** 1.5, self.most)
                force = np.zeros(n)
                force[np.argmin(s.pose.gap)] = r
                out.append({"displacement": np.zeros((n, 3)), "force": force, "reaction": r})
            return out


def test_a_pose_model_given_the_force_is_measured_where_it_meets_it(tiny_presses, tmp_path):
    """``--to-force``: each sample's object starts where the FEM started pressing it and is
    pressed on until the model's reaction meets the sample's: a model whose reaction is the
    FEM's at the FEM's depth puts it at that depth (depth error within the meshes' facets and
    force control's tolerance); one whose reaction never reaches the force is counted with why,
    never dropped; a model that takes a force is refused.
    """
    from stmpl import predictor
    from stmpl.data.dataset import Dataset
    from stmpl.pipeline.evaluate import evaluate, evaluate_to_force, scenes_of

    ds = Dataset(tiny_presses)
    (scene,), _ = scenes_of(ds, "test", given="pose")
    model = _Hertzian.Model(scene.pose.depth, scene.meta["reaction"])
    s = evaluate_to_force(model, ds, "test")
    assert s["samples"] == 1 and abs(s["depth_err"][0]) < 0.03  # mm
    assert 2 <= s["answers"][0] <= 20 and s["peak_err"][0] == pytest.approx(-100.0)  # no dent
    weak = _Hertzian.Model(
        scene.pose.depth, scene.meta["reaction"], most=0.5 * scene.meta["reaction"]
    )
    with pytest.raises(Exception, match="met the force of none of the 1 samples"):
        evaluate_to_force(weak, ds, "test")
    md = evaluate({"strong": model}, ds, "test", out=tmp_path / "t.md", to_force=True)
    assert "depth err mm" in md and "reaction err" not in md
    with pytest.raises(ValueError, match="takes a force: --to-force measures models given"):
        evaluate_to_force(predictor.create("naive", ds.part), ds, "test")
