"""One call from a load on a body part to FEM displacements: mesh at a named resolution, refined
around the load, then Newton with load continuation.

Resolutions (chosen by the convergence study in ``benchmarks/fem_speed.py``; see
``benchmarks/RESULTS.md``): ``subdivisions`` levels of midpoint refinement within
``refine_radius`` of the loaded vertices, ``layers`` element layers through the thickness,
element ``order`` 1 (4-node) or 2 (10-node tetrahedra).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, replace

import numpy as np

from fem.finer import meshed
from fem.layers import preset
from fem.material import NeoHookean
from fem.mesh import ShellMesh, room, shell_mesh
from fem.solver import Solution, Solver, SolverOptions
from stmpl.part import BodyPart


@dataclass(frozen=True)
class Resolution:
    """Mesh resolution of a tissue shell (see :func:`fem.mesh.shell_mesh`)."""

    subdivisions: int
    layers: int
    refine_radius: float | None = 0.03
    order: int = 1

    def to_dict(self) -> dict:
        return asdict(self)


RESOLUTIONS = {
    "coarse": Resolution(2, 3, order=1),
    "medium": Resolution(1, 1, order=2),
    "fine": Resolution(1, 2, order=2),
    "finest": Resolution(2, 3, order=2),
}
REFERENCE = "fine"
"""The resolution datasets are generated at: the coarsest whose loaded-vertex displacement lies
within 2 % of the finest mesh's (benchmarks/fem_speed.py)."""


def resolution(res: str | Resolution | dict) -> Resolution:
    """A :class:`Resolution` from a name, a mapping or itself."""
    if isinstance(res, Resolution):
        return res
    if isinstance(res, str):
        if res == "reference":
            res = REFERENCE
        if res not in RESOLUTIONS:
            raise ValueError(
                f"unknown resolution {res!r}; choose one of "
                f"{sorted(RESOLUTIONS) + ['reference']} or give "
                "subdivisions/layers/refine_radius"
            )
        return RESOLUTIONS[res]
    if isinstance(res, dict):
        unknown = set(res) - {"subdivisions", "layers", "refine_radius", "order"}
        if unknown:
            raise ValueError(f"unknown resolution keys {sorted(unknown)}")
        return Resolution(**res)
    raise TypeError(f"resolution must be a name, a dict or a Resolution, got {type(res)}")


def mesh_for_load(
    part: BodyPart,
    thickness: np.ndarray,
    force: np.ndarray,
    res: str | Resolution | dict = "reference",
) -> ShellMesh:
    """The tissue shell for one load pattern ``force`` ``(N,)``, refined around its vertices."""
    force = np.asarray(force, dtype=float)
    loaded = np.flatnonzero(force > 0)
    if len(loaded) == 0:
        raise ValueError("the load has no loaded vertex (force is zero everywhere)")
    return tissue_mesh(part, thickness, res, near=part.vertices[loaded])[0]


def check_order(tissue: str, res) -> None:
    """Refuse linear elements for a layered preset: its nearly incompressible layers lock in
    them (``ValueError`` naming the fix).
    """
    stack = preset(tissue)
    if stack is not None and resolution(res).order == 1:
        raise ValueError(
            f"the {stack.name} tissue's nearly incompressible layers lock in linear (order 1) "
            "elements, an answer many times too stiff: use a resolution of order 2 (medium, "
            "fine, finest or reference)"
        )


def tissue_mesh(
    part: BodyPart,
    thickness: np.ndarray,
    res: str | Resolution | dict = "reference",
    tissue: str = "paper",
    phenotype: dict | None = None,
    near: np.ndarray | None = None,
):
    """``(mesh, material)``: the tissue shell of ``part`` refined near the points ``near``
    ``(K, 3)`` (m), and its material. ``tissue``: a preset of :mod:`fem.layers`; ``paper``
    meshes ``thickness`` ``(N,)`` (m) in the resolution's even layers of neo-Hookean gel (the
    material is then ``None``: the solver's default), a layered preset meshes its skin, fat and
    muscle (the scene's thickness being the skin and fat) with its own element layers, in
    quadratic elements only (linear ones lock: a fingertip 3 mm into the forearm carried 6.2 N
    in them against 0.41 N in quadratic ones).
    """
    r = resolution(res)
    refine = dict(
        subdivisions=r.subdivisions,
        refine_near=None if r.refine_radius is None or near is None else near,
        refine_radius=r.refine_radius or 0.03,
    )
    stack = preset(tissue)
    if stack is None:
        return shell_mesh(part, thickness, layers=r.layers, **refine), None
    check_order(tissue, r)
    layers = stack.thicknesses(thickness, phenotype, room(part))
    mesh = shell_mesh(
        part,
        layers.sum(0),
        layers=stack.elements,
        fractions=stack.fractions(layers),
        **refine,
    )
    return mesh, stack.material(mesh.tet_layers)


def press_solver(
    part: BodyPart,
    thickness: np.ndarray,
    res: str | Resolution | dict,
    tissue: str,
    phenotype: dict | None,
    near: np.ndarray,
    options: SolverOptions | None = None,
    material=None,
) -> Solver:
    """The solver of an object pressed on ``part`` (thickness ``(N,)`` m), its tissue meshed
    and refined near the points ``near`` ``(K, 3)`` (m) as :func:`tissue_mesh` does, its
    answers given on ``part``. Where it answers ``part`` exactly (:func:`fem.finer.meshed`),
    the tissue is meshed on the part ``part`` was subdivided from, with one level of
    refinement more: the same mesh near the object, a coarser one where the tissue barely
    moves. ``material``: for the paper's gel (default neo-Hookean).
    """
    r = resolution(res)
    on, t = meshed(part, thickness, r.order)
    if on is not part:
        r = replace(r, subdivisions=r.subdivisions + 1)
    mesh, layered = tissue_mesh(on, t, r, tissue, phenotype, near)
    if layered is not None:
        material = layered
    return Solver(mesh, material or NeoHookean(), options=options, order=r.order, answer_on=part)


def simulate(
    part: BodyPart,
    thickness: np.ndarray,
    force: np.ndarray,
    totals=None,
    res: str | Resolution | dict = "reference",
    material=None,
    options: SolverOptions | None = None,
    tissue: str = "paper",
    phenotype: dict | None = None,
) -> tuple[ShellMesh, list[Solution]]:
    """Solve the load pattern ``force`` ``(N,)`` (N per vertex) on ``part`` with per-vertex
    ``thickness`` ``(N,)`` (m), scaled to each total force in ``totals`` (N, rising; default
    the pattern's own total), by continuation. Returns the mesh and one :class:`Solution` per
    level; failed levels carry their reason and no displacement.

    ``tissue``: ``"paper"`` (the gel of ``material``, default neo-Hookean E = 1 kPa) or a layered
    preset of :mod:`fem.layers` (its own laws; ``phenotype`` shapes its layers).
    """
    force = np.asarray(force, dtype=float)
    loaded = np.flatnonzero(force > 0)
    if len(loaded) == 0:
        raise ValueError("the load has no loaded vertex (force is zero everywhere)")
    if tissue != "paper" and material is not None:
        raise ValueError(f"the {tissue} preset brings its own laws: give no material with it")
    mesh, layered = tissue_mesh(part, thickness, res, tissue, phenotype, part.vertices[loaded])
    solver = Solver(
        mesh,
        layered or (material if material is not None else NeoHookean()),
        options=options,
        order=resolution(res).order,
    )
    totals = [float(force.sum())] if totals is None else [float(t) for t in totals]
    if any(b <= a for a, b in zip(totals, totals[1:])):
        raise ValueError(f"totals must rise strictly, got {totals}")
    return mesh, solver.continuation(force, totals)
