"""The stability sweep on the tube: scenes along each axis, the FEM's failures said with their
time, every predictor's errors and flags, the pictures and the report."""

import numpy as np
import pytest

from stmpl import stability
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


def test_the_sweep_flags_what_lies_outside(tiny_dataset, tmp_path):
    from stmpl.train import train

    ckpt = train({"model": "naive", "data": str(tiny_dataset), "out": str(tmp_path / "n"),
                  "epochs": 5, "batch": 16, "lr": 0.02}, progress=False)
    cfg = {"name": "s", "kind": "stability", "body": TUBE, "part": "tube",
           "predictors": [str(ckpt)],                # named by its file: ckpt.stem
           "fem": {"res": {"subdivisions": 1, "layers": 1, "order": 1}, "levels": 1},
           "base": BASE, "axes": {"force": [0.05, 0.15, 3.0], "thickness": [3.0],
                                         "size": [1.0]},       # 1 mm: between vertices
           "out": str(tmp_path / "report")}
    from stmpl.ablate import run

    res = run(cfg, progress=False)                   # through stmpl ablate's entry
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


def test_bad_sweeps_are_named():
    with pytest.raises(ValueError, match="unknown stability axis 'colour'"):
        stability.read_config({"predictors": ["fem"], "axes": {"colour": [1]}})
    with pytest.raises(ValueError, match="must be a list of numbers"):
        stability.read_config({"predictors": ["fem"], "axes": {"force": [True]}})
    with pytest.raises(ValueError, match="at least one predictor"):
        stability.read_config({"axes": {"force": [1.0]}})


@pytest.mark.parametrize("config", ["configs/ablation/stability_fine.yaml"])
def test_the_shipped_envelopes_flag_every_sweep_point_where_a_model_breaks_its_promise(arm,
                                                                                      config):
    """The committed sweep of the shipped models, driven through today's envelopes: at every
    point where the FEM failed, or where a learned model's answer broke the per-scene promise
    (zoo.SCENE_PROMISE) or was physically impossible, that model flags the scene as outside (or
    refuses it). The envelope is what the sweep set; this keeps it so."""
    import json
    import pathlib

    from stmpl import zoo

    cfg = stability.read_config(config)
    points = json.loads((pathlib.Path(cfg["out"]) / "points.json").read_text()).values()
    part = arm.subdivided(int(cfg["body"].get("subdivisions", 0)))
    learned = {}
    for spec in cfg["predictors"]:
        p = zoo.read(spec[4:])
        if p.name in ("gnn", "uv_unet"):
            learned[spec[4:]] = p
    assert learned
    checked = broke = 0
    for rec in points:
        scene = stability.scene_at(part, cfg["base"], rec["axis"], rec["value"])
        assert scene.total_force == pytest.approx(rec["total"], rel=1e-6)   # the same scene
        for name, p in learned.items():
            r = rec["predictors"][name]
            if "refused" in r:
                continue
            bad = (not rec["fem"]["ok"] or not r["physical"]
                   or r["rel_mee"] > zoo.SCENE_PROMISE["rel_mee"]
                   or abs(r["peak_err"]) > zoo.SCENE_PROMISE["peak_err"])
            why = p.envelope.reasons(scene)
            checked += 1
            if bad:
                broke += 1
                assert why, (f"{name} at {rec['axis']}={rec['value']}: broke its promise "
                             f"({r.get('rel_mee')}, {r.get('peak_err')}) inside its envelope")
    assert checked >= 80 and broke >= 20, (checked, broke)
