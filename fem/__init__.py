"""FEM ground truth: tissue-shell tetrahedral meshes, Neo-Hookean material, Newton solver and
dataset generation, and the ``fem`` predictor. ``stmpl`` never imports it: it plugs in through
entry points (``pyproject.toml``).

>>> from fem import simulate
>>> mesh, sols = simulate(part, thickness, force, totals=[0.1, 0.2], res="reference")
>>> sols[-1].ok, sols[-1].reason, sols[-1].part_displacement(mesh)   # (N, 3) m

Lower level: ``shell_mesh(part, thickness, layers, subdivisions, refine_near=...)`` and
``Solver(mesh, material, order=2).solve(force)`` / ``.continuation(force, totals)``.
"""

from fem.linear_solvers import available_linear_solvers
from fem.material import LinearElastic, NeoHookean, material
from fem.mesh import Quality, ShellMesh, shell_mesh
from fem.simulate import REFERENCE, RESOLUTIONS, Resolution, simulate
from fem.solver import Solution, Solver, SolverOptions

__all__ = [
    "LinearElastic",
    "NeoHookean",
    "material",
    "Quality",
    "ShellMesh",
    "shell_mesh",
    "Solution",
    "Solver",
    "SolverOptions",
    "available_linear_solvers",
    "REFERENCE",
    "RESOLUTIONS",
    "Resolution",
    "simulate",
]
