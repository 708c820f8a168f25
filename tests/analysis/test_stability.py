"""The stability sweep on the tube: scenes along each axis, the FEM's failures said with their
time, every predictor's errors and flags, the pictures and the report.
"""

import numpy as np
import pytest

from stmpl.analysis import stability
from stmpl.body.spec import part_from_spec

TUBE = {"model": "tube", "radius": 0.04, "length": 0.2, "n_around": 16, "n_along": 12}
BASE = {"radius": 0.02, "total": 0.1, "thickness_mm": 7.5, "uv": [0.5, 0.5]}


def test_scenes_along_each_axis_change_only_that_axis():
    part = part_from_spec(TUBE, "tube")
    s = stability.scene_at(part, BASE, "force", 0.3)
    assert s.total_force == pytest.approx(0.3)
    p = stability.scene_at(part, BASE, "pressure", 0.5)
    assert p.total_force / p.load.area == pytest.approx(500.0)
    a, b = (stability.scene_at(part, BASE, "size", r) for r in (15, 30))
    assert a.total_force / a.load.area == pytest.approx(b.total_force / b.load.area)
    assert b.load.area > a.load.area
    assert np.allclose(stability.scene_at(part, BASE, "thickness", 10).thickness, 0.010)
    assert stability.scene_at(part, BASE, "seam", 0.5).load.kind == "seam_disk"
    c = stability.scene_at(part, BASE, "contacts", 3)
    from stmpl.envelope import contacts

    assert len(contacts(part, c.force)) == 3 and c.total_force == pytest.approx(0.1)
    v = stability.scene_at(part, BASE, "variation", 10.0)
    assert np.ptp(v.thickness) == pytest.approx(0.005) and v.thickness.min() >= 0.005


def test_the_sweep_flags_what_lies_outside(tiny_dataset, tmp_path, monkeypatch):
    from stmpl import envelope
    from stmpl.pipeline.train import train

    # a promise Naive keeps on its validation split: the sweep's axes alone decide here
    monkeypatch.setattr(envelope, "SCENE_PROMISE", {"rel_mee": 1e9, "peak_err": 1e9})
    ckpt = train(
        {
            "model": "naive",
            "data": str(tiny_dataset),
            "out": str(tmp_path / "n"),
            "epochs": 5,
            "batch": 16,
            "lr": 0.02,
        },
        progress=False,
    )
    cfg = {
        "name": "s",
        "kind": "stability",
        "body": TUBE,
        "part": "tube",
        "predictors": [str(ckpt)],  # named by its file: ckpt.stem
        "fem": {"res": {"subdivisions": 1, "layers": 1, "order": 1}, "levels": 1},
        "base": BASE,
        "axes": {
            "force": [0.05, 0.15, 3.0],
            "thickness": [3.0],
            "size": [1.0],
        },  # 1 mm: between vertices
        "out": str(tmp_path / "report"),
    }
    from stmpl.analysis.ablation import run

    res = run(cfg, progress=False)  # through stmpl ablate's entry
    pts = {(p["axis"], p["value"]): p for p in res["points"]}
    light = pts[("force", 0.05)]
    assert light["fem"]["ok"] and light["predictors"][ckpt.stem]["inside"]
    assert 0 < light["predictors"][ckpt.stem]["rel_mee"] < 100
    heavy = pts[("force", 3.0)]["predictors"][ckpt.stem]
    assert heavy["inside"] is False and any("force of a contact" in w for w in heavy["outside"])
    thin = pts[("thickness", 3.0)]["predictors"][ckpt.stem]
    assert thin["inside"] is False and "tissue thickness 3 mm < 5 mm" in thin["outside"][0]
    for p in (q for q in res["points"] if "skipped" not in q):
        assert p["fem"]["ok"] or (p["fem"]["reason"] and p["fem"]["seconds"] < 120)
    assert "touches no vertex" in pts[("size", 1.0)]["skipped"]
    out = tmp_path / "report"
    for f in ("stability_force.png", "stability_thickness.png", "envelope_map.png"):
        assert (out / f).stat().st_size > 10_000
    md = (out / "stability.md").read_text()
    assert "## force" in md and " out" in md and "not made on this mesh" in md
    assert stability.verdict({"physical": False}) == "impossible"
    assert stability.verdict({"physical": True, "rel_mee": 0.5, "peak_err": -7.0}) == "<=1 %"
    assert stability.peak_off({"physical": True, "rel_mee": 0.5, "peak_err": -7.0})
    # another model: measured afresh, the FEM's answers come from the cache, not a new solve
    other = train(
        {
            "model": "naive",
            "data": str(tiny_dataset),
            "out": str(tmp_path / "m"),
            "epochs": 2,
            "batch": 16,
            "lr": 0.02,
        },
        progress=False,
    )
    from stmpl import predictor

    fem_class = type(predictor.create("fem", res=cfg["fem"]["res"]))
    calls, solve = [], fem_class.predict
    monkeypatch.setattr(
        fem_class, "predict", lambda self, *a, **k: calls.append(1) or solve(self, *a, **k)
    )
    again = run({**cfg, "predictors": [str(other)]}, progress=False)
    assert not calls and len(again["points"]) == len(res["points"])
    import json

    kept = json.loads((tmp_path / "report" / "points.json").read_text())  # no stale records
    assert {n for r in kept.values() for n in r.get("predictors", {})} == {other.stem}
    np.testing.assert_allclose(
        [p["fem"].get("deepest_mm", 0) for p in again["points"] if "skipped" not in p],
        [p["fem"].get("deepest_mm", 0) for p in res["points"] if "skipped" not in p],
    )


def test_bad_sweeps_are_named():
    with pytest.raises(ValueError, match="unknown stability axis 'colour'"):
        stability.read_config({"predictors": ["fem"], "axes": {"colour": [1]}})
    with pytest.raises(ValueError, match="must be a list of numbers"):
        stability.read_config({"predictors": ["fem"], "axes": {"force": [True]}})
    with pytest.raises(ValueError, match="at least one predictor"):
        stability.read_config({"axes": {"force": [1.0]}})


@pytest.mark.parametrize(
    "config", ["configs/ablation/stability.yaml", "configs/ablation/stability_fine.yaml"]
)
def test_the_shipped_envelopes_flag_every_sweep_point_where_a_model_breaks_its_promise(arm, config):
    """The committed sweeps of the shipped models, driven through today's envelopes (with the
    caps `stmpl zoo limit` set from them): at every point where the FEM failed, or where a
    learned model's answer broke the per-scene promise (stmpl.envelope.SCENE_PROMISE) or was
    physically impossible, in any record of that point, the model flags the scene as outside (or
    refuses it).
    """
    from stmpl.analysis import limits
    from stmpl.pipeline import zoo

    cfg = stability.read_config(config)
    part = arm.subdivided(int(cfg["body"].get("subdivisions", 0)))
    learned = {s[4:]: zoo.read(s[4:]) for s in cfg["predictors"]}
    learned = {n: p for n, p in learned.items() if p.name in ("gnn", "uv_unet")}
    assert learned
    checked = broken = 0
    for scene, recs in limits.measured(cfg, part):
        assert scene.total_force == pytest.approx(recs[0]["total"], rel=1e-6)  # the same scene
        for name, p in learned.items():
            if all("refused" in r["predictors"][name] for r in recs):
                continue
            checked += 1
            if any(limits.broke(r, name) for r in recs):
                broken += 1
                assert p.envelope.reasons(scene), (
                    f"{name} at {recs[0]['axis']}={recs[0]['value']}: broke its promise inside "
                    "its envelope"
                )
    assert checked >= 80 and broken >= 20, (checked, broken)


def test_a_limit_caps_every_box_and_survives_a_round_trip(ds):
    from stmpl.envelope import Envelope
    from stmpl.pipeline.evaluate import scenes_of

    scenes, _ = scenes_of(ds, "train")
    env = Envelope.of(
        ds.part, np.stack([s.thickness for s in scenes]), np.stack([s.force for s in scenes])
    )
    inside = [s for s in scenes if not env.reasons(s)]
    from stmpl.envelope import features

    cp = sorted(max(features(ds.part, s.thickness, s.force)["contact_pressure"]) for s in inside)
    env.limit("contact_pressure", cp[len(cp) // 2], "a test")
    again = Envelope.from_dict(env.to_dict())
    for e in (env, again):
        out = [s for s in inside if e.reasons(s)]
        assert 0 < len(out) < len(inside)
        assert all(
            "where it was measured to stop keeping its promise: a test" in e.reasons(s)[0]
            for s in out
        )
    with pytest.raises(ValueError, match="max or range axis"):
        env.limit("rim_distance", 0.01)


@pytest.mark.parametrize(
    "text,message",
    [
        (None, "run the stability sweep"),
        ("{not json", "is not the sweep's JSON"),
        ("[1, 2]", "must map points to records"),
        ('{"a": {"axis": "force"}}', "point 'a' is not a sweep record"),
    ],
)
def test_a_missing_or_malformed_sweep_is_named(tmp_path, arm, text, message):
    from stmpl.analysis import limits

    cfg = stability.read_config("configs/ablation/stability.yaml")
    cfg = {**cfg, "out": str(tmp_path)}
    if text is not None:
        (tmp_path / "points.json").write_text(text)
    with pytest.raises((ValueError, FileNotFoundError), match=message):
        limits.measured(cfg, arm)
