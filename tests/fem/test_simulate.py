import numpy as np
import pytest

from fem.simulate import RESOLUTIONS, Resolution, mesh_for_load, resolution, simulate
from stmpl.body.primitives import tube


def test_resolutions_by_name_dict_and_errors():
    assert resolution("reference") == RESOLUTIONS["fine"]
    assert resolution({"subdivisions": 1, "layers": 2, "order": 2}) == Resolution(1, 2, 0.03, 2)
    with pytest.raises(ValueError, match="unknown resolution"):
        resolution("ultra")
    with pytest.raises(ValueError, match="unknown resolution keys"):
        resolution({"levels": 2})


def test_simulate_refines_around_the_load_and_continues():
    part = tube(radius=0.04, length=0.2, n_around=16, n_along=12)
    force = np.zeros(part.n_vertices)
    force[[90, 91]] = 0.05
    th = np.full(part.n_vertices, 0.008)
    mesh, sols = simulate(part, th, force, totals=[0.05, 0.1], res="medium")
    assert [s.ok for s in sols] == [True, True]
    assert mesh.n_skin < 2 * part.n_vertices  # refined only near the load
    u1, u2 = (np.linalg.norm(s.part_displacement(mesh)[90]) for s in sols)
    assert 1.5 < u2 / u1 < 2.5  # nearly linear at these loads
    with pytest.raises(ValueError, match="rise"):
        simulate(part, th, force, totals=[0.1, 0.05])
    with pytest.raises(ValueError, match="no loaded vertex"):
        mesh_for_load(part, th, np.zeros(part.n_vertices))
