"""The local FEM: solve only the tissue a load moves.

A press moves the tissue within a few thicknesses of the contact; the rest of the part stays put
to well under a percent of the deepest displacement. The local solve cuts the part to the
vertices within ``margin`` of a loaded vertex (whole faces; the patches holding a load), holds
the cut through the whole thickness as the part's own rims are held, and solves that patch. The
answer is checked at the cut: if the vertices one edge inside it moved more than ``tolerance``
of the deepest displacement, the cut was too tight and the margin grows by ``grow`` and the
solve runs again (up to the whole part). The ring is judged at the last force level that
converged: a patch whose every level failed grows too (the tight cut may be what failed), while a
failure above a still ring is the load's own and stands. Vertices outside the patch get zero
displacement.

The first margin grows with the load and the tissue (:func:`stmpl.reach.first_margin`): the
contact's radius plus ``thicknesses`` times the largest thickness under it. How far a load
reaches is :mod:`stmpl.reach`'s to say; this module solves the patch it gives.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from fem.force_control import press_to_force
from fem.material import NeoHookean
from fem.simulate import resolution, simulate, tissue_mesh
from fem.solver import Solver
from stmpl.geometry import boundary_loops
from stmpl.part import BodyPart
from stmpl.reach import GROW, RING_TOLERANCE, first_margin, near


@dataclass(frozen=True, eq=False)
class Patch:
    """A part cut to a region: ``part`` (the patch as a :class:`BodyPart`, its cut among its
    rims), ``vertices`` ``(n,)`` the patch's vertices in the whole part, ``margin`` (m) and
    ``ring`` the patch vertices one edge inside the cut.
    """

    part: BodyPart
    vertices: np.ndarray
    margin: float
    ring: np.ndarray
    whole: bool = False

    def lift(self, u: np.ndarray, n: int) -> np.ndarray:
        """``(n, 3)`` displacement of the whole part from the patch's ``(k, 3)`` (zero outside)."""
        out = np.zeros((n, 3))
        out[self.vertices] = u
        return out


def patch(part: BodyPart, force: np.ndarray, margin: float) -> Patch:
    """The patch of ``part`` within ``margin`` (m, straight-line) of a loaded vertex: the faces
    whose three vertices are that near, the connected pieces that hold a load.
    """
    loaded = np.flatnonzero(force > 0)
    close = near(part, force, margin)
    on = np.zeros(part.n_vertices, bool)
    on[loaded] = True  # the faces around a loaded vertex, however long, belong
    fidx = np.flatnonzero(close[part.faces].all(1) | on[part.faces].any(1))
    n = part.n_vertices
    if len(fidx) == len(part.faces):
        return Patch(part, np.arange(n), margin, np.zeros(0, np.int64), whole=True)
    faces = part.faces[fidx]
    # pieces joined through edges (not through single shared vertices)
    fi = np.repeat(np.arange(len(faces)), 3)
    g = coo_matrix((np.ones(len(fi)), (fi, faces.ravel())), shape=(len(faces), n)).tocsr()
    adj = g @ g.T
    adj.data = (adj.data >= 2).astype(float)
    adj.eliminate_zeros()
    _, label = connected_components(adj, directed=False)
    holds = np.unique(label[np.isin(faces, loaded).any(1)])
    fidx = fidx[np.isin(label, holds)]
    verts = np.unique(part.faces[fidx])
    if len(fidx) == len(part.faces):
        return Patch(part, np.arange(n), margin, np.zeros(0, np.int64), whole=True)
    sub = _sub_part(part, verts, fidx)
    cut = np.concatenate(sub.rims) if sub.rims else np.zeros(0, np.int64)
    if part.rims:  # the part's own rims are held in the whole solve too
        cut = cut[~np.isin(verts[cut], np.concatenate(part.rims))]
    e = sub.edges
    on = np.zeros(sub.n_vertices, bool)
    on[cut] = True
    ring = np.unique(
        np.concatenate([e[on[e[:, 0]] & ~on[e[:, 1]], 1], e[on[e[:, 1]] & ~on[e[:, 0]], 0]])
    )
    return Patch(sub, verts, margin, ring)


def _sub_part(part: BodyPart, verts: np.ndarray, fidx: np.ndarray) -> BodyPart:
    """The patch of ``part`` made of faces ``fidx`` on vertices ``verts`` (whole-part indices),
    normals from the whole part, rims = every boundary loop of the patch.
    """
    where = np.full(part.n_vertices, -1)
    where[verts] = np.arange(len(verts))
    fuv = part.face_uv[fidx]
    corners = np.unique(fuv)
    cwhere = np.full(len(part.uv), -1)
    cwhere[corners] = np.arange(len(corners))
    f = where[part.faces[fidx]]
    return dataclasses.replace(
        part,
        name=f"{part.name}[patch]",
        vertices=part.vertices[verts],
        faces=f,
        normals=part.normals[verts],
        uv=part.uv[corners],
        face_uv=cwhere[fuv],
        uv_vertex=where[part.uv_vertex[corners]],
        rims=boundary_loops(f),
        axis=None,
        body_index=None if part.body_index is None else part.body_index[verts],
    )


@dataclass
class LocalResult:
    """What a local solve did: the patch solved last, each attempt's margin, size, time and the
    share the ring next to the cut moved (relative to the deepest displacement).
    """

    patch: Patch
    attempts: list = field(default_factory=list)

    def summary(self) -> dict:
        return {
            "margin_m": self.patch.margin,
            "vertices": int(len(self.patch.vertices)),
            "whole": self.patch.whole,
            "attempts": self.attempts,
        }


FAILED_ATTEMPTS = 2
"""A solve in which no level converges is tried once more on a patch grown by ``GROW`` (the cut
might have been what failed); when that fails too the failure is the load's own and is
returned, instead of growing on to the whole part (which took minutes on the fine arm for a
load that buckles)."""


def simulate_local(
    part: BodyPart,
    thickness,
    force,
    totals=None,
    res="reference",
    material=None,
    options=None,
    tissue: str = "paper",
    phenotype: dict | None = None,
    margin: float | None = None,
    tolerance: float = RING_TOLERANCE,
    grow: float = GROW,
):
    """:func:`fem.simulate.simulate` on the patch the load moves (of the ``tissue`` preset, shaped
    by ``phenotype``). Returns ``(mesh, solutions,
    result)``: the patch's mesh and solutions (``Solution.part_displacement`` on the patch),
    and a :class:`LocalResult`; :meth:`Patch.lift` gives the whole part's displacement.
    """
    t = np.asarray(thickness, dtype=float)
    f = np.asarray(force, dtype=float)
    m = first_margin(part, t, f) if margin is None else float(margin)
    result = None
    failed = 0  # attempts in a row in which no level converged
    while True:
        p = patch(part, f, m)
        t0 = time.perf_counter()
        mesh, sols = simulate(
            p.part, t[p.vertices], f[p.vertices], totals, res, material, options, tissue, phenotype
        )
        ok = [x for x in sols if x.ok]
        moved = _ring_moved(p, ok[-1].part_displacement(mesh) if ok else None)
        att = {
            "margin_m": m,
            "vertices": int(len(p.vertices)),
            "whole": p.whole,
            "seconds": time.perf_counter() - t0,
            "ring_moved": moved,
        }
        result = result or LocalResult(p)
        result.patch = p
        result.attempts.append(att)
        failed = failed + 1 if not any(x.ok for x in sols) else 0
        if p.whole or moved <= tolerance or failed >= FAILED_ATTEMPTS:
            return mesh, sols, result
        m *= grow


def _ring_moved(p: Patch, u: np.ndarray | None) -> float:
    """How far the ring next to the cut moved in ``u`` ``(k, 3)`` (the patch's displacement at
    the last answer that converged), relative to the deepest displacement: ``inf`` when none
    converged (``u`` ``None``: a patch too tight may be what failed, so it grows; a failure with
    the ring still is the load's own) or the patch has no ring (all of it on the cut); 0 for
    the whole part.
    """
    if p.whole:
        return 0.0
    if u is None or len(p.ring) == 0:
        return float("inf")
    norm = np.linalg.norm(u, axis=1)
    return float(norm[p.ring].max() / max(norm.max(), 1e-30))


def press_local(
    part: BodyPart,
    thickness,
    shape,
    direction,
    force: float,
    res="reference",
    tissue: str = "forearm",
    phenotype: dict | None = None,
    margin: float | None = None,
    tolerance: float = RING_TOLERANCE,
    grow: float = GROW,
    footprint: float = 0.003,
    **kwargs,
):
    """A rigid ``shape`` pushed along ``direction`` (see :mod:`fem.contact`) until it carries
    ``force`` (N), solved on the patch it moves: the object's footprint (the vertices it would
    reach ``footprint`` m deep into the rest state) stands for the load in :func:`patch`, and
    the patch grows as for a load when the ring next to the cut moves. ``kwargs`` go to
    :func:`fem.force_control.press_to_force`. Returns ``(answer, result)``: the
    :class:`~fem.contact.Pressed` answer with its displacement ``(N, 3)`` and pressure ``(N,)``
    on the whole part (zero outside the patch; its ``state`` is the patch's), and a
    :class:`LocalResult`.
    """
    t = np.asarray(thickness, dtype=float)
    phi, _, _ = shape.pushed(footprint, direction).distance(part.vertices)
    touched = phi < 0
    if not touched.any():
        touched[np.argmin(phi)] = True
    f = touched.astype(float)  # the footprint, as a load pattern: how far a press reaches
    m = first_margin(part, t, f) if margin is None else float(margin)
    result, failed = None, 0
    while True:
        p = patch(part, f, m)
        t0 = time.perf_counter()
        mesh, layered = tissue_mesh(
            p.part, t[p.vertices], res, tissue, phenotype, part.vertices[touched]
        )
        solver = Solver(mesh, layered or NeoHookean(), order=resolution(res).order)
        answer = press_to_force(solver, shape, direction, force, **kwargs)
        moved = _ring_moved(p, answer.displacement if answer.ok else None)
        result = result or LocalResult(p)
        result.patch = p
        result.attempts.append(
            {
                "margin_m": m,
                "vertices": int(len(p.vertices)),
                "whole": p.whole,
                "seconds": time.perf_counter() - t0,
                "ring_moved": moved,
            }
        )
        failed = failed + 1 if not answer.ok else 0
        if p.whole or moved <= tolerance or failed >= FAILED_ATTEMPTS:
            break
        m *= grow
    if not answer.ok:
        return answer, result
    pressure = np.zeros(part.n_vertices)
    pressure[p.vertices] = answer.pressure
    lifted = p.lift(answer.displacement, part.n_vertices)
    return dataclasses.replace(answer, displacement=lifted, pressure=pressure), result
