"""FEM ground truth: tissue-shell tetrahedral meshes, Neo-Hookean material, Newton solver and
dataset generation. ``stmpl`` never imports it at module level.

>>> from fem import shell_mesh, Solver
>>> mesh = shell_mesh(part, thickness, layers=3, subdivisions=2, refine_near=loaded_points)
>>> sol = Solver(mesh).solve(force)          # sol.ok, sol.reason, sol.part_displacement(mesh)
"""

from fem.material import LinearElastic, NeoHookean, material
from fem.mesh import Quality, ShellMesh, shell_mesh
from fem.solver import Solution, Solver, SolverOptions, available_linear_solvers

__all__ = ["LinearElastic", "NeoHookean", "material", "Quality", "ShellMesh", "shell_mesh",
           "Solution", "Solver", "SolverOptions", "available_linear_solvers"]
