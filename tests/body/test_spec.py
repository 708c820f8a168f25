"""Bodies and parts from a spec (stmpl/body/spec.py): the one place a description becomes a
body.
"""

import numpy as np
import pytest

from stmpl.body import sheet, tube
from stmpl.body.spec import body_from_spec, part_from_spec


def test_primitives_from_their_spec():
    part = part_from_spec(
        {"model": "tube", "radius": 0.05, "length": 0.2, "n_around": 10, "n_along": 5}, "ignored"
    )
    np.testing.assert_allclose(part.vertices, tube(0.05, 0.2, 10, 5).vertices)
    assert (
        part_from_spec({"model": "sheet", "nx": 4, "ny": 3}, "x").n_vertices
        == sheet(nx=4, ny=3).n_vertices
    )


def test_anny_from_its_spec(anny_body):
    part = part_from_spec({"model": "anny", "phenotype": {"weight": 0.5}}, "left_arm")
    np.testing.assert_allclose(part.vertices, anny_body.part("left_arm").vertices)


@pytest.mark.parametrize(
    "spec,message",
    [
        ({"model": "mannequin"}, "body.model must be one of"),
        ("anny", "body.model must be one of"),
        ({"model": "tube", "radius": 0.04, "colour": "red"}, r"unknown body keys \['colour'\]"),
        ({"model": "smpl"}, "needs the model file's path"),
    ],
)
def test_bad_specs_are_named(spec, message):
    with pytest.raises(ValueError, match=message):
        part_from_spec(spec, "left_arm")


def test_a_primitive_is_not_a_body():
    with pytest.raises(ValueError, match="a single part, not a body"):
        body_from_spec({"model": "tube"})
