"""Shared fixtures: one Anny body per session (its assets build once into $ANNY_CACHE_DIR) and a
fresh stmpl part cache, so part extraction really runs in the tests.
"""

import os

import numpy as np
import pytest


@pytest.fixture(scope="session", autouse=True)
def _stmpl_cache(tmp_path_factory):
    old = os.environ.get("STMPL_CACHE_DIR")
    os.environ["STMPL_CACHE_DIR"] = str(tmp_path_factory.mktemp("stmpl-cache"))
    yield
    if old is None:
        os.environ.pop("STMPL_CACHE_DIR", None)
    else:
        os.environ["STMPL_CACHE_DIR"] = old


@pytest.fixture(scope="session")
def anny_body():
    from stmpl.body import AnnyBody

    return AnnyBody()


@pytest.fixture(scope="session")
def arm(anny_body):
    return anny_body.part("left_arm")


@pytest.fixture
def rng():
    return np.random.default_rng(0)


TINY_DATA = {
    "name": "tiny",
    "body": {"model": "tube", "radius": 0.04, "length": 0.2, "n_around": 16, "n_along": 12},
    "part": "tube",
    "thickness_mm": [5.0, 10.0],
    "resolution": {"subdivisions": 1, "layers": 1, "refine_radius": 0.03, "order": 1},
    "forces": [0.05, 0.1, 0.2],
    "placements": {
        "disk": {"centres": 8, "radii": [0.02]},
        "band": {"at": [0.3, 0.6], "widths": [0.03]},
    },
    "shard_tasks": 4,
    "parallel": {"backend": "serial", "workers": 1},
}


@pytest.fixture
def tiny_config():
    """A factory of small dataset configs on the tube: ``tiny_config(forces=[0.05])`` is
    :data:`TINY_DATA` with those keys replaced.
    """
    import copy

    return lambda **over: {**copy.deepcopy(TINY_DATA), **over}


@pytest.fixture(scope="session")
def tiny_dataset(tmp_path_factory):
    """A real FEM dataset on an analytic tube (10 placements x 2 thicknesses x 3 forces), made
    once per session in about a second.
    """
    from fem.generate import generate

    out = tmp_path_factory.mktemp("data") / "tiny"
    generate(TINY_DATA, out, progress=False)
    return out


TINY_PRESSES = {
    **{k: v for k, v in TINY_DATA.items() if k not in ("placements", "forces", "thickness_mm")},
    "name": "tiny_presses",
    "resolution": {"subdivisions": 1, "layers": 2, "refine_radius": 0.03, "order": 2},
    "thickness_mm": [7.5],
    "forces": [0.3],
    "tissue": "forearm",
    "placements": {
        "press_sphere": {"centres": 2, "radii": [0.008]},
        "press_disk": {"centres": 1, "radii": [0.01], "rounding": 0.001},
    },
}


@pytest.fixture(scope="session")
def tiny_presses(tmp_path_factory):
    """A real FEM dataset of objects pressed by force control into the tube: an 8 mm ball at
    two places and a 10 mm rounded disk at a third (0.3 N on 7.5 mm of the layered forearm; a
    place for each split), made once per session.
    """
    from fem.generate import generate

    out = tmp_path_factory.mktemp("data") / "tiny_presses"
    generate(TINY_PRESSES, out, progress=False)
    return out


def pressed_ball(part, radius: float = 0.05, depth: float = 8e-3):
    """A posed scene: a ball of ``radius`` (m; 5 cm spans several of the tube's 2 cm edges)
    ``depth`` (m) into 7.5 mm of tissue at the vertex farthest from the part's rims.
    """
    from stmpl import tissue
    from stmpl.contact import objects
    from stmpl.contact.posing import posed

    ball = objects.sphere(radius)
    at = int(np.argmax(part.rim_distance))
    pose = objects.press(part, ball, at, depth=depth)
    return posed(part, tissue.constant(part, 0.0075), ball, pose)


TINY_MODELS = {
    "naive": {},
    "linear": {},
    "uv_unet": {"size": 64, "width": 4, "depth": 3},
    "gnn": {"latent": 16, "steps": 2},
}
"""Options of tiny, fast versions of each learned model."""
VARIANTS = {
    "": {},
    "per_newton": {"per_newton": True},
    "prior": {"per_newton": True, "prior": "linear", "loss": "relative"},
}


@pytest.fixture(scope="session")
def ds(tiny_dataset):
    """The tiny dataset, opened."""
    from stmpl.data.dataset import Dataset

    return Dataset(tiny_dataset)


@pytest.fixture
def make():
    """A factory of seeded tiny predictors on a dataset's part: ``make("gnn/prior", ds)``
    (``kind/variant``; ``fem`` is a coarse FEM). Models with a computed part are fitted.
    """

    def _make(name, ds):
        from stmpl import predictor

        if name == "fem":
            return predictor.create("fem", res={"subdivisions": 1, "layers": 1, "order": 1})
        import torch

        torch.manual_seed(0)
        kind, _, variant = name.partition("/")
        p = predictor.create(kind, ds.part, {**TINY_MODELS[kind], **VARIANTS[variant]})
        if hasattr(p, "fit"):
            p.fit(ds, progress=False)
        return p

    return _make
