"""Models of every body of one mesh (option ``geometry``): trained on several bodies at once
(tubes of one mesh at other radii here), they serve a body no dataset holds, with the linear
prior solved on that body; models of one body refuse it by name.
"""

import numpy as np
import pytest

from fem.generate import generate
from stmpl import predictor
from stmpl.pipeline.train import train

RADII = (0.035, 0.05)
OPTIONS = {"gnn": {"latent": 16, "steps": 2}, "uv_unet": {"size": 64, "width": 4, "depth": 3}}
GENERAL = {
    "geometry": True,
    "prior": "linear",
    "operator": "on_demand",
    "per_newton": True,
    "loss": "relative",
}


@pytest.fixture(scope="module")
def bodies(tmp_path_factory):
    """Two tube datasets of one mesh, radii 35 and 50 mm, with the linear FEM's answers."""
    from tests.conftest import TINY_DATA

    root = tmp_path_factory.mktemp("bodies")
    out = []
    for r in RADII:
        cfg = {
            **TINY_DATA,
            "name": f"tube{int(r * 1e3)}",
            "thickness_mm": [7.5],
            "forces": [0.05, 0.1],
            "linear": True,
            "body": {**TINY_DATA["body"], "radius": r},
        }
        generate(cfg, root / cfg["name"], progress=False)
        out.append(str(root / cfg["name"]))
    return out


def _tube(radius, n_around=16):
    from stmpl.body import primitives

    return primitives.tube(radius=radius, length=0.2, n_around=n_around, n_along=12)


def _scene(part, force=0.1):
    from stmpl import loads
    from stmpl.scene import Scene

    at = int(np.argmin(np.abs(part.axial - np.median(part.axial))))
    return Scene(part, np.full(part.n_vertices, 7.5e-3), loads.disk(part, at, 0.02, force).force)


@pytest.mark.parametrize("kind", ["gnn", "uv_unet"])
def test_a_model_of_every_body_serves_an_unseen_one(bodies, tmp_path, kind):
    """Trained on the 35 and 50 mm tubes, it answers on a 42 mm tube within a few per cent of
    the FEM there (its own linear FEM, solved for that body, carries the answer), and not as it
    would on the 35 mm tube.
    """
    from fem.predictor import FEMPredictor
    from stmpl.metrics import sample_metrics

    path = train(
        {
            "name": kind,
            "model": kind,
            "data": bodies,
            "epochs": 2,
            "batch": 8,
            "options": {**OPTIONS[kind], **GENERAL},
            "out": str(tmp_path / kind),
        },
        progress=False,
    )
    p = predictor.read(path)
    assert p.general and len(p.body_parts) == 1  # a checkpoint knows its own only
    unseen = _scene(_tube(0.042))
    d = p.predict(unseen)
    fem = FEMPredictor(res={"subdivisions": 1, "layers": 1, "order": 1}).predict(unseen)
    m = sample_metrics(fem.displacement, d.displacement)
    assert m["rel_mee"] < 5.0 and abs(m["peak_err"]) < 8.0
    assert len(p.body_parts) == 2  # the unseen body: slot 1
    on_template = p.predict(_scene(p.part)).displacement
    assert (
        np.abs(
            np.linalg.norm(d.displacement, axis=1).max() - np.linalg.norm(on_template, axis=1).max()
        )
        > 1e-6
    )
    with pytest.raises(ValueError, match="another mesh"):
        p.predict(_scene(_tube(0.042, n_around=12)))


def test_models_of_one_body_refuse_others(bodies, tmp_path):
    with pytest.raises(ValueError, match="spans 2 bodies"):
        train(
            {
                "name": "g",
                "model": "gnn",
                "data": bodies,
                "epochs": 1,
                "options": OPTIONS["gnn"],
                "out": str(tmp_path / "g"),
            },
            progress=False,
        )
    path = train(
        {
            "name": "g",
            "model": "gnn",
            "data": bodies[0],
            "epochs": 1,
            "options": OPTIONS["gnn"],
            "out": str(tmp_path / "g1"),
        },
        progress=False,
    )
    with pytest.raises(ValueError, match="another body part"):
        predictor.read(path).predict(_scene(_tube(0.042)))
    with pytest.raises(ValueError, match="on_demand"):
        predictor.get("gnn").options({"geometry": True, "prior": "linear"})


def test_the_envelope_knows_the_bodies_sizes(bodies, tmp_path):
    """The skin areas of the training bodies bound the bodies the model vouches for: a tube
    between them is inside, one twice as wide is not (and says why).
    """
    path = train(
        {
            "name": "g",
            "model": "gnn",
            "data": bodies,
            "epochs": 1,
            "batch": 8,
            "options": {**OPTIONS["gnn"], **GENERAL},
            "out": str(tmp_path / "g"),
        },
        progress=False,
    )
    p = predictor.read(path)
    lo, hi = p.envelope.boxes["training"]["skin_area"]
    assert lo == pytest.approx(_tube(RADII[0]).vertex_areas.sum(), rel=1e-6)
    assert hi == pytest.approx(_tube(RADII[1]).vertex_areas.sum(), rel=1e-6)
    assert p.envelope.reasons(_scene(_tube(0.042))) == []
    assert any("skin area" in why for why in p.envelope.reasons(_scene(_tube(0.1))))
