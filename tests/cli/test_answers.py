"""The runner behind ``stmpl predict`` and ``simulate``: which predictors, on which tissue, with
which friction.
"""

import argparse

import pytest

from stmpl.cli.answers import predictors


def _args(**given) -> argparse.Namespace:
    base = dict(
        device="cpu",
        res="reference",
        levels=1,
        fidelity="full",
        tissue=None,
        friction=None,
        engine="default",
    )
    return argparse.Namespace(**{**base, **given})


@pytest.mark.parametrize(
    "model, tissue, friction",
    [("zoo:gnn_forearm_grips", "forearm", 0.5), ("zoo:gnn_arm_bodies", "paper", 0.0)],
)
def test_the_fem_meets_the_objects_as_the_learned_model_s_data_did(model, tissue, friction):
    """Unless told, the FEM beside a model takes the model's tissue and the friction its data was
    solved with (the grip set's dry skin, 0.5), so ``--compare`` compares like with like; a model
    of force-given scenes records none (frictionless).
    """
    args = _args()
    _, fem = predictors(args, [model, "fem"])
    assert (args.tissue, args.friction) == (tissue, friction)
    assert fem.tissue == tissue and fem.friction == friction


def test_a_friction_given_is_kept():
    args = _args(friction=0.2)
    _, fem = predictors(args, ["zoo:gnn_forearm_grips", "fem"])
    assert args.friction == 0.2 and fem.friction == 0.2
