"""The ground truth as a predictor: the tissue-shell FEM behind :class:`stmpl.predictor.Predictor`
(registered as ``fem`` through the ``stmpl.predictors`` entry point).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from fem.contact import press
from fem.force_control import press_to_force
from fem.friction import coefficient
from fem.layers import bound, preset
from fem.local import simulate_local
from fem.mesh import ShellMesh
from fem.objects import at_pose
from fem.shapes import ROUNDING
from fem.simulate import check_order, press_solver, resolution, simulate
from fem.solver import Solution
from stmpl.contact.posing import moved
from stmpl.predictor import BasePredictor, PredictionFailed, check_fidelity
from stmpl.scene import Scene
from stmpl.tissue import Bound


class FEMFailed(PredictionFailed):
    """The FEM could not solve a scene; the message says why."""


@dataclass(frozen=True)
class Shell:
    """The last solved tissue shell: its mesh and the solution per continuation level (for
    pictures of the section and ParaView files).
    """

    mesh: ShellMesh
    solutions: list[Solution]

    @property
    def displacement(self) -> np.ndarray:
        """``(M, 3)`` displacement of the mesh nodes at the last level, m."""
        return self.solutions[-1].displacement


class FEMPredictor(BasePredictor):
    """The tissue-shell FEM (see :mod:`fem`) as a predictor.

    Args:
        res: mesh resolution name or :class:`fem.simulate.Resolution` (default the reference).
        levels: continuation levels from rest to each scene's force.
        material, options: passed to the solver.
        fidelity: ``"full"`` solves the whole part; ``"auto"`` only the patch the load moves,
            grown until the tissue at its cut stays still (:mod:`fem.local`).
        tissue: ``"paper"`` (the gel) or a layered preset of :mod:`fem.layers`, its layers
            shaped by anny's ``phenotype``.
        friction: Coulomb's coefficient between a posed scene's objects and the skin
            (:mod:`fem.friction`; 0, the default, is frictionless).

    A scene given by a pose (:mod:`stmpl.pose`) is answered by pressing its objects, from first
    contact, to that pose (a grip's hand closing along its path) in contact with the skin
    (:func:`fem.contact.press`, on the whole part at either fidelity): the answer carries the
    contact force on each vertex and the objects' reaction (a grip's: its squeeze).

    A failed solve raises :class:`FEMFailed` (never a displacement). ``Deformation.info`` holds
    the last level's diagnostics and ``levels``, one diagnostics dict per continuation level;
    :attr:`last_shell` keeps the last scene's mesh and solutions.
    """

    name = "fem"
    batched = False
    takes = ("force", "pose")

    @property
    def bound(self) -> Bound:
        """How far an answer may compress its tissue (:func:`fem.layers.bound`): where the FEM
        itself fails an answer.
        """
        return bound(self.tissue)

    def __init__(
        self,
        res="reference",
        levels: int = 1,
        material=None,
        options=None,
        fidelity: str = "full",
        tissue: str = "paper",
        phenotype: dict | None = None,
        friction: float = 0.0,
    ):
        self.res = resolution(res)
        self.friction = coefficient(friction)
        preset(tissue)  # an unknown name is refused here, not at the first scene
        check_order(tissue, self.res)
        self.tissue, self.phenotype = tissue, dict(phenotype or {})
        if isinstance(levels, bool) or int(levels) != levels or levels < 1:
            raise ValueError(f"levels must be an integer >= 1, got {levels!r}")
        self._fidelity = check_fidelity(fidelity)
        self.levels, self.material, self.options = int(levels), material, options
        self.last_shell: Shell | None = None
        self._last: dict = {}
        self._ready: dict = {}  # answers to_force found, by their scene

    def predict_batch(self, scenes: list[Scene]) -> list[np.ndarray]:
        out = []
        for s in scenes:
            if s.pose is not None:
                out.append(self._pressed(s))
                continue
            total = float(s.force.sum())
            if total <= 0:
                out.append(np.zeros((s.part.n_vertices, 3)))
                self._last[id(s)] = {"fem": "no load"}
                continue
            totals = total * np.arange(1, self.levels + 1) / self.levels
            local = None
            setup = (totals, self.res, self.material, self.options, self.tissue, self.phenotype)
            try:
                if self.fidelity == "auto":
                    mesh, sols, local = simulate_local(s.part, s.thickness, s.force, *setup)
                else:
                    mesh, sols = simulate(s.part, s.thickness, s.force, *setup)
            except ValueError as e:  # a scene it cannot mesh (a thickness that folds)
                raise FEMFailed(f"the FEM cannot build the tissue for this scene: {e}") from e
            sol = sols[-1]
            if not sol.ok:
                raise FEMFailed(f"the FEM solve failed at {sol.total_force:.3g} N: {sol.reason}")
            self.last_shell = Shell(mesh, sols)
            self._last[id(s)] = {
                **{k: v for k, v in sol.diagnostics().items() if k != "reason"},
                "levels": [x.diagnostics() for x in sols],
                "mesh": {"nodes": mesh.n_nodes, "tets": int(len(mesh.tets))},
                "local": None if local is None else local.summary(),
            }
            u = sol.part_displacement(mesh)
            out.append(u if local is None else local.patch.lift(u, s.part.n_vertices))
        return out

    def _pressed(self, s: Scene) -> dict:
        """The answer to a posed scene: its objects pressed to their pose (or the answer
        :meth:`to_force` found for it).
        """
        n = s.part.n_vertices
        ready = self._ready.pop(id(s), None)
        if ready is None:
            shape, depth = self._at_pose(s)
            if depth == 0.0:
                self._last[id(s)] = {"fem": "no contact: the objects do not reach the skin"}
                return {"displacement": np.zeros((n, 3)), "force": np.zeros(n), "reaction": 0.0}
            solver = self._solver(s)
            (a,) = press(solver, shape, s.pose.direction, [depth], friction=self.friction)
            if not a.ok:
                raise FEMFailed(f"the FEM press failed at {1e3 * depth:.3g} mm deep: {a.reason}")
        else:
            a, solver, depth = ready
        mesh = solver.mesh
        self.last_shell = None  # a press keeps no continuation levels
        self._last[id(s)] = {
            "depth": depth,
            "reaction": a.reaction,
            "contact_area": a.area,
            "penetration": a.penetration,
            "min_det_F": a.min_det_F,
            "compression": a.compression,
            "iterations": a.iterations,
            "updates": a.updates,
            "fidelity": "full"
            if self.fidelity == "full"
            else "full: a pose is pressed on the whole part, whatever the fidelity",
            "mesh": {
                "nodes": mesh.n_nodes,
                "tets": int(len(mesh.tets)),
                "skin_vertices": mesh.part.n_vertices,  # the part meshed (fem.finer)
            },
        }
        force = a.pressure * s.part.vertex_areas
        return {"displacement": a.displacement, "force": force, "reaction": a.reaction}

    def _at_pose(self, s: Scene):
        """:func:`fem.objects.at_pose` of a posed scene, a pose it cannot press said so."""
        try:
            return at_pose(s.part, s.pose)
        except ValueError as e:
            raise FEMFailed(f"the FEM cannot press this pose: {e}") from e

    def _solver(self, s: Scene):
        """The solver of a posed scene's tissue, its mesh refined where the objects press."""
        near = s.part.vertices[_pressed_skin(s.pose)]
        try:
            return press_solver(
                s.part,
                s.thickness,
                self.res,
                self.tissue,
                self.phenotype,
                near,
                self.options,
                self.material,
            )
        except ValueError as e:
            raise FEMFailed(f"the FEM cannot build the tissue for this scene: {e}") from e

    def to_force(self, scene: Scene, force: float, rtol: float = 0.005, strict=None):
        """The answer to ``scene``'s objects (given by their pose) pressed along their press (a
        grip: closed along its paths) until their reaction is ``force`` (N) within ``rtol``:
        the FEM's own force control (:func:`fem.force_control.press_to_force`), from the
        objects at first contact, instead of a search over whole presses
        (:func:`stmpl.contact.force_control.to_force`, which hands a FEM predictor here).
        The answer's scene is the objects at the depth found; ``info["force_control"]`` as
        there. A force it cannot carry raises :class:`FEMFailed` with the reason.
        """
        t0 = time.perf_counter()
        start, extra = scene, 0.0
        shape, depth = self._at_pose(scene)
        if depth == 0.0:  # not yet into the skin: from a pose that is
            extra = max(float(scene.pose.gap.min()), 0.0) + 2 * ROUNDING
            start = moved(scene, extra)
            shape, depth = self._at_pose(start)
            if depth == 0.0:
                raise FEMFailed("force control: the objects do not reach the skin along their way")
        solver = self._solver(start)
        a = press_to_force(
            solver, shape, start.pose.direction, force, rtol=rtol, friction=self.friction
        )
        if not a.ok:
            raise FEMFailed(f"the FEM could not press the objects to {force:g} N: {a.reason}")
        target = moved(start, a.depth - depth)
        self._ready[id(target)] = (a, solver, a.depth)
        try:
            answer = self.predict(target, strict=strict)
        finally:  # never left for another scene that might take its id
            self._ready.pop(id(target), None)
        seconds = time.perf_counter() - t0
        answer.info["seconds"] = seconds  # the answer's time: the whole force control's
        answer.info["force_control"] = {
            "force": float(force),
            "reaction": float(a.reaction),
            "moved_mm": 1e3 * (extra + a.depth - depth),
            "answers": None,  # one press, its depth found by the FEM's own force control
            "seconds": seconds,
        }
        return answer

    def info(self, scene: Scene) -> dict:
        return {
            "resolution": self.res.to_dict(),
            "tissue": self.tissue,
            **self._last.pop(id(scene), {}),
        }


def _pressed_skin(pose) -> np.ndarray:
    """``(K,)`` the skin vertices a pose presses, where the FEM refines its mesh: near the
    objects' nearest point, and for a grip within 5 mm of any finger.
    """
    if pose.closing:
        close = np.flatnonzero(pose.gap < 0.005)
        if len(close):
            return close
    return pose.near()
