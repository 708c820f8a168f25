"""SMPLBody on small SMPL-format files made here (SMPL itself is never shipped)."""

import pickle
import sys
import types

import numpy as np
import pytest
import scipy.sparse as sp

from stmpl.body import SMPLBody, tube
from stmpl.body.smpl_body import JOINTS


def _model(n_around=12, n_along=9):
    """A tube 'left arm' along +x, skinned to left_shoulder (upper half) and left_elbow."""
    t = tube(radius=0.04, length=0.5, n_around=n_around, n_along=n_along)
    v = t.vertices[:, [2, 0, 1]] + [0.2, 0.0, 0.0]  # axis along +x
    n = len(v)
    weights = np.zeros((n, 24))
    upper = v[:, 0] < 0.45
    weights[upper, JOINTS.index("left_shoulder")] = 1.0
    weights[~upper, JOINTS.index("left_elbow")] = 1.0
    jr = np.zeros((24, n))
    jr[:, 0] = 1.0
    jr[JOINTS.index("left_shoulder")] = 0
    jr[JOINTS.index("left_shoulder"), :n_around] = 1.0 / n_around  # first ring
    jr[JOINTS.index("left_elbow")] = 0
    mid = (n_along // 2) * n_around
    jr[JOINTS.index("left_elbow"), mid : mid + n_around] = 1.0 / n_around
    jr[JOINTS.index("left_wrist")] = 0
    jr[JOINTS.index("left_wrist"), -n_around:] = 1.0 / n_around
    radial = np.c_[np.zeros(n), v[:, 1:]] / 0.04
    shapedirs = np.zeros((n, 3, 10))
    shapedirs[:, :, 1] = 0.005 * radial  # beta_2 fattens the arm by 5 mm per unit
    kintree = np.stack([np.r_[-1, np.zeros(23, int)], np.arange(24)])
    data = dict(
        v_template=v,
        shapedirs=shapedirs,
        J_regressor=sp.csc_matrix(jr),
        weights=weights,
        kintree_table=kintree,
        f=t.faces,
    )
    return data, t


def _write_obj(path, t, faces):
    lines = [f"vt {u} {w}" for u, w in t.uv]
    lines += [
        "f " + " ".join(f"{a + 1}/{b + 1}" for a, b in zip(fv, ft))
        for fv, ft in zip(faces, t.face_uv)
    ]
    path.write_text("\n".join(lines))


@pytest.fixture
def smpl_files(tmp_path):
    data, t = _model()
    np.savez(tmp_path / "model.npz", **data)
    _write_obj(tmp_path / "uv.obj", t, data["f"])
    return tmp_path / "model.npz", tmp_path / "uv.obj", data, t


def test_reads_npz_and_cuts_the_left_arm(smpl_files, tmp_path):
    model, uv, data, t = smpl_files
    body = SMPLBody(model, uv, cache_dir=tmp_path / "c")
    arm = body.part("left_arm")
    assert arm.n_vertices == len(data["v_template"]) and arm.n_faces == len(data["f"])
    assert len(arm.seam_groups) == 9  # the tube's seam survives the reader
    np.testing.assert_allclose(arm.axis[0], data["v_template"][:12].mean(0), atol=1e-12)
    assert arm.axial.max() == pytest.approx(0.5)


def test_betas_apply_shape_blend_shapes(smpl_files, tmp_path):
    model, uv, data, _ = smpl_files
    fat = SMPLBody(model, uv, betas=[0.0, 2.0], cache_dir=tmp_path)
    r = np.linalg.norm(fat.shaped_vertices()[:, 1:], axis=1)
    np.testing.assert_allclose(r, 0.04 + 2 * 0.005)
    assert (
        fat.part("left_arm").vertices[:, 1:].std()
        > SMPLBody(model, uv, cache_dir=tmp_path).part("left_arm").vertices[:, 1:].std()
    )


def test_reads_chumpy_pickles(smpl_files, tmp_path):
    _, uv, data, _ = smpl_files
    # a stand-in for chumpy's Ch: an object whose state holds the array as 'x'
    mod = types.ModuleType("chumpy.ch")

    class Ch:
        def __init__(self, x):
            self.x = x

    Ch.__module__, Ch.__qualname__ = "chumpy.ch", "Ch"
    mod.Ch = Ch
    sys.modules["chumpy"], sys.modules["chumpy.ch"] = types.ModuleType("chumpy"), mod
    try:
        d = dict(data, v_template=Ch(data["v_template"]), shapedirs=Ch(data["shapedirs"]))
        (tmp_path / "model.pkl").write_bytes(pickle.dumps(d, protocol=2))
    finally:
        del sys.modules["chumpy"], sys.modules["chumpy.ch"]
    a = SMPLBody(tmp_path / "model.pkl", uv, cache_dir=tmp_path).part("left_arm")
    np.testing.assert_allclose(a.vertices, data["v_template"])


@pytest.mark.parametrize(
    "change,message",
    [
        (lambda d: d.pop("J_regressor"), r"lacks keys \['J_regressor'\]"),
        (lambda d: d.update(v_template=d["v_template"][:, :2]), r"v_template must be \(V, 3\)"),
        (lambda d: d.update(shapedirs=d["shapedirs"][:5]), "shapedirs must be"),
        (lambda d: d.update(weights=d["weights"][:, :20]), "J_regressor must be"),
        (lambda d: d.update(kintree_table=d["kintree_table"][:1]), "kintree_table must be"),
        (lambda d: d.update(f=d["f"] + 10_000), "f must be"),
    ],
)
def test_bad_smpl_files_are_named(tmp_path, change, message):
    data, _ = _model()
    change(data)
    np.savez(tmp_path / "bad.npz", **data)
    with pytest.raises(ValueError, match=message):
        SMPLBody(tmp_path / "bad.npz")


def test_missing_files_and_uvs(smpl_files, tmp_path):
    model, uv, data, t = smpl_files
    with pytest.raises(FileNotFoundError, match="SMPL model file not found"):
        SMPLBody(tmp_path / "nope.npz")
    with pytest.raises(ValueError, match="no UVs"):
        SMPLBody(model, cache_dir=tmp_path).part("left_arm")
    _write_obj(tmp_path / "wrong.obj", t, data["f"][::-1][:-1])
    with pytest.raises(ValueError, match="faces do not match"):
        SMPLBody(model, tmp_path / "wrong.obj")
    with pytest.raises(ValueError, match="at most 10 values"):
        SMPLBody(model, uv, betas=np.zeros(11))
    with pytest.raises(ValueError, match="no whole face"):
        SMPLBody(model, uv, cache_dir=tmp_path).part("right_arm")


def test_an_smpl_format_body_goes_through_the_whole_pipeline(smpl_files, tmp_path):
    """A user's SMPL-format files take the same path as anny: a dataset made by the FEM on its
    left arm, a GNN (on the linear FEM prior) trained on it, a checkpoint that predicts a fresh
    scene on that body closer to the FEM than Naive does, and that refuses a body of another
    topology with an error that says so.
    """
    import warnings

    from fem.generate import generate
    from stmpl import loads, predictor, tissue
    from stmpl.body.spec import part_from_spec
    from stmpl.data.dataset import Dataset
    from stmpl.pipeline.train import train
    from stmpl.scene import Scene

    model, uv, _, _ = smpl_files
    body = {"model": "smpl", "path": str(model), "uv_path": str(uv)}
    data = tmp_path / "smpl_data"
    generate(
        {
            "name": "smpl_tiny",
            "body": body,
            "part": "left_arm",
            "thickness_mm": [5.0, 10.0],
            "resolution": {"subdivisions": 1, "layers": 1, "refine_radius": 0.03, "order": 1},
            "forces": [0.05, 0.1, 0.2],
            "placements": {"disk": {"centres": 8, "radii": [0.03]}},
            "shard_tasks": 4,
            "parallel": {"backend": "serial", "workers": 1},
        },
        data,
        progress=False,
    )
    ds = Dataset(data)
    assert ds.card["config"]["body"]["model"] == "smpl" and len(ds.arrays("train")["force"]) > 0
    runs = {}
    for kind, options, epochs in (
        (
            "gnn",
            {"latent": 16, "steps": 2, "per_newton": True, "prior": "linear", "loss": "relative"},
            30,
        ),
        ("naive", {}, 30),
    ):
        runs[kind] = predictor.read(
            train(
                {
                    "name": f"smpl_{kind}",
                    "model": kind,
                    "options": options,
                    "data": str(data),
                    "epochs": epochs,
                    "batch": 8,
                    "lr": 1e-3,
                    "out": str(tmp_path / "runs" / kind),
                },
                progress=False,
            )
        )
    part = part_from_spec(body, "left_arm")
    scene = Scene.from_load(
        part,
        tissue.constant(part, 0.0075),
        loads.disk(part, uv=(0.4, 0.5), radius=0.03, total=0.15),
    )
    truth = predictor.create("fem", res=ds.card["config"]["resolution"]).predict(scene)
    peak = truth.magnitude.max()
    err = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # 7.5 mm lies between the levels
        for kind, p in runs.items():
            d = p.predict(scene)
            err[kind] = float(
                np.linalg.norm(d.displacement - truth.displacement, axis=1).mean() / peak
            )
    assert err["gnn"] < 0.5 * err["naive"] and err["gnn"] < 0.05, err
    other = tube(radius=0.04, length=0.5, n_around=10, n_along=9)
    with pytest.raises(ValueError, match="another body part"):
        runs["gnn"].predict(
            Scene.from_load(
                other,
                tissue.constant(other, 0.0075),
                loads.disk(other, uv=(0.5, 0.5), radius=0.03, total=0.1),
            )
        )
