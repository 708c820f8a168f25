"""FEM ground truth: tissue-shell tetrahedral meshes, Neo-Hookean material, Newton solver and
dataset generation, and the ``fem`` predictor. ``stmpl`` never imports it: it plugs in through
entry points (``pyproject.toml``).

>>> from fem.simulate import simulate
>>> mesh, sols = simulate(part, thickness, force, totals=[0.1, 0.2], res="reference")
>>> sols[-1].ok, sols[-1].reason, sols[-1].part_displacement(mesh)   # (N, 3) m

Lower level: ``shell_mesh(part, thickness, layers, subdivisions, refine_near=...)`` and
``Solver(mesh, material, order=2).solve(force)`` / ``.continuation(force, totals)``.
"""

from stmpl.lazy import exports

PUBLIC = {
    "available_linear_solvers": "fem.linear_solvers",
    "LinearElastic": "fem.material",
    "NeoHookean": "fem.material",
    "Quality": "fem.mesh",
    "ShellMesh": "fem.mesh",
    "shell_mesh": "fem.mesh",
    "REFERENCE": "fem.simulate",
    "RESOLUTIONS": "fem.simulate",
    "Resolution": "fem.simulate",
    "Solution": "fem.solution",
    "Solver": "fem.solver",
    "SolverOptions": "fem.options",
}
"""The package's names and the module each comes from, imported on first use (so that the
command line's registration of the FEM's commands stays light). ``simulate`` and ``material``,
which share their module's name, come from their modules: ``from fem.simulate import
simulate``."""

__all__ = list(PUBLIC)
__getattr__, __dir__ = exports(__name__, PUBLIC)
