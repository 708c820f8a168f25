"""Predictors named on the command line (stmpl/pipeline/spec.py)."""

import pytest

from stmpl.pipeline.spec import label, predictor_from_spec


def test_fem_specs():
    p = predictor_from_spec("fem:medium")
    assert p.name == "fem" and p.res.layers == 1 and p.res.order == 2
    assert predictor_from_spec("fem").res == predictor_from_spec("fem:reference").res


def test_labels():
    assert label("zoo:gnn_arm") == "gnn_arm"
    assert label("runs/x/model_a.safetensors") == "model_a"
    assert label("fem:coarse") == "fem:coarse"


@pytest.mark.parametrize(
    "spec,error,message",
    [
        ("oracle", ValueError, "unknown predictor 'oracle'"),
        ("fem:ultra", ValueError, "unknown resolution 'ultra'"),
        ("missing.safetensors", FileNotFoundError, "checkpoint not found"),
    ],
)
def test_bad_specs_are_named(spec, error, message):
    with pytest.raises(error, match=message):
        predictor_from_spec(spec)
