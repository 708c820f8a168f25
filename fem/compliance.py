"""The linear compliance (Green's) operator of a tissue shell: the small-strain displacement of
every part vertex under a unit normal force on each vertex, precomputed once by FEM.

For a load ``F`` ``(N,)`` (N per vertex, along the inward normal, spread as a traction exactly
as the ground truth spreads it) the linear response is ``u_i = sum_j G_ij F_j`` with
``G`` ``(N, N, 3)`` in m/N. It is the tangent of the Neo-Hookean solve at rest, so it is exact in
the limit of light loads and drifts from the FEM as strains grow; the classical way to make FEM
real-time (condensation onto the loaded surface), and a prior the learned models correct.

The mesh is the resolution's, refined over the whole skin (the ground truth refines only near the
load, which every vertex is here). One factorisation, then ``N`` right-hand sides in blocks.

On demand (:func:`local_compliance`, :class:`ColumnStore`), only the columns a scene loads are
solved, on the patch of tissue they move (:mod:`fem.local`): a unit press on a vertex moves the
tissue within a few thicknesses of it, so a patch's factorisation is a small fraction of the
whole part's (on the once-subdivided arm: 394k free DOFs, 11 s to factorise in single
precision, then about 0.1 s per column in blocks of 128, each refined to double precision).
"""

from __future__ import annotations

import hashlib
import json
import pathlib
import time

import numpy as np

from fem.krylov import BLOCK
from fem.local import patch
from fem.material import material
from fem.material import material as make_material
from fem.simulate import resolution, tissue_mesh
from fem.solver import Solver, SolverOptions
from fem.verification import quarter_disk
from stmpl.body.model import default_cache_dir
from stmpl.files import atomic_savez
from stmpl.part import BodyPart
from stmpl.reach import GROW, first_margin


def compliance(
    part: BodyPart,
    thickness: float | np.ndarray,
    res="reference",
    material=None,
    options: SolverOptions | None = None,
    block: int = 128,
    progress=None,
    columns=None,
    tissue: str = "paper",
    phenotype: dict | None = None,
) -> np.ndarray:
    """``(N, N, 3)`` compliance ``G`` (m/N): ``G[i, j]`` is vertex ``i``'s displacement under a
    unit normal force on vertex ``j`` of a layer of ``thickness`` (m, a scalar or ``(N,)``).
    With ``columns`` ``(k,)`` (vertex indices) only those: ``(N, k, 3)``.

    ``material``: a material object or its dict (its tangent at rest is used, so Neo-Hookean and
    linear give the same operator); ``options``: the ground truth's :class:`SolverOptions` (load
    mode, fixed rims, linear solver); ``progress``: a callable taking the number of columns done.
    ``tissue``: ``"paper"`` (a layer of ``material``), or a layered preset of :mod:`fem.layers`
    meshed as the FEM meshes it (:func:`fem.simulate.tissue_mesh`, ``phenotype`` shaping its
    layers; ``thickness`` its skin and fat): its laws' tangent at rest, so the linear FEM of that
    tissue. Raises ``ArithmeticError`` (from the factorisation) if the stiffness is not positive
    definite.
    """
    n = part.n_vertices
    t = np.broadcast_to(np.asarray(thickness, dtype=float), (n,)).copy()
    r = resolution(res)
    if tissue != "paper" and material is not None:
        raise ValueError(f"the {tissue} preset brings its own laws: give no material with it")
    mesh, layered = tissue_mesh(part, t, r, tissue, phenotype)  # refined nowhere: every column
    mat = make_material(**material) if isinstance(material, dict) else material
    solver = Solver(mesh, layered or mat, options=options, order=r.order)
    u0 = np.zeros((solver.n_all, 3))
    _, K = solver.assemble(u0, u0)
    solver.linear.factor(K)
    want = np.arange(n) if columns is None else np.asarray(columns, dtype=np.int64)
    G = np.zeros((n, len(want), 3))
    nodes = mesh.part_nodes
    for lo in range(0, len(want), block):
        at = np.arange(lo, min(lo + block, len(want)))
        X = solver.linear.solve(unit_loads(solver, want[at]))
        u = np.zeros((solver.n_all * 3, len(at)))
        u[solver.free] = X
        G[:, at] = u.reshape(solver.n_all, 3, len(at))[nodes].transpose(0, 2, 1)
        if progress is not None:
            progress(len(at))
    if not np.all(np.isfinite(G)):
        raise ArithmeticError("the compliance operator has non-finite entries")
    return G


def unit_loads(solver: Solver, columns: np.ndarray) -> np.ndarray:
    """``(n_free, k)`` the free DOFs' share of ``solver``'s external forces under a unit normal
    force on each part vertex of ``columns`` ``(k,)``, in Fortran order: the right-hand sides
    of a block of compliance columns.
    """
    columns = np.asarray(columns, dtype=np.int64)
    if solver.order == 1 or solver.options.force_mode == "nodal":
        out = np.empty((len(solver.free), len(columns)), order="F")
        for k, j in enumerate(columns):
            e = np.zeros(solver.mesh.part.n_vertices)
            e[j] = 1.0
            out[:, k] = solver.external_forces(e).ravel()[solver.free]
        return out
    return solver.force_operator[solver.free][:, columns].toarray(order="F")


def sparsify(G: np.ndarray, tol: float = 1e-3) -> tuple[np.ndarray, np.ndarray, float]:
    """The pattern of ``G`` ``(L, N, N, 3)`` (L thickness levels) worth keeping: pairs ``(i, j)``
    where ``|G_ij|`` reaches ``tol`` times the level's largest entry at some level.

    Returns ``(index (2, nnz) [i; j], values (L, nnz, 3), dropped)``, ``dropped`` the largest
    left-out ``|G_ij|`` relative to its level's largest (<= ``tol``).
    """
    mag = np.linalg.norm(G, axis=-1)  # (L, N, N)
    rel = mag / mag.reshape(len(G), -1).max(1)[:, None, None]
    keep = (rel >= tol).any(0)
    i, j = np.nonzero(keep)
    dropped = float(np.where(keep[None], 0.0, rel).max())
    return np.stack([i, j]), G[:, i, j], dropped


COLUMN_TOLERANCE = 0.01
"""On-demand columns: how far a column may move the vertices next to its patch's cut, relative to
the column's own largest displacement. Measured on the plain arm (10 random columns at 5 and
10 mm): 0.02 leaves columns within 5e-4 / 2e-3 of their largest entry of the whole-part
solve, 0.005 within 3e-4 / 8e-4 at 1.5-2x the time; the stored operator drops entries under 1e-3
of the level's largest."""


COLUMN_THICKNESSES = 3.0
"""On-demand columns start from the patch within this many thicknesses of the loaded vertices
(plus their radius and two edges), where the local FEM starts at six (its answer is held to half
the tolerance); the ring test above still grows it where that is too tight. Measured on a 2 cm
disk at 6.5 mm on a new body, mid-forearm and near the wrist: six thicknesses cut
779 / 498 of the 2109 vertices, the ring moved 2-3e-4 of a column's largest and the load's
answer lay within 1e-4 of the whole part's deepest; three cut 579 / 445, the ring moved 2e-3 and
the answer within 9e-4 of the whole part's, in 20-25 % less time."""


def local_compliance(
    part: BodyPart,
    thickness: float,
    columns,
    res="reference",
    material=None,
    options: SolverOptions | None = None,
    margin: float | None = None,
    tolerance: float = COLUMN_TOLERANCE,
    grow: float | None = None,
    progress=None,
    tissue: str = "paper",
    phenotype: dict | None = None,
) -> tuple[np.ndarray, dict]:
    """The columns ``(N, k, 3)`` (m/N) of :func:`compliance` for the vertices ``columns``
    ``(k,)`` of a uniform layer ``thickness`` (m), solved on the patch within ``margin`` of them
    (default :func:`stmpl.reach.first_margin` at :data:`COLUMN_THICKNESSES`); the patch grows by
    ``grow`` (default :data:`stmpl.reach.GROW`) until every column moves the ring next to its cut
    by at most ``tolerance`` of its own largest displacement, up to the whole part. Rows outside
    the patch are zero. Returns the columns and a summary (margin, patch vertices, attempts,
    seconds). ``progress``: a callable taking the number of columns solved, on each attempt;
    ``tissue``, ``phenotype``: as for :func:`compliance`.
    """
    n = part.n_vertices
    cols = np.unique(np.asarray(columns, dtype=np.int64))
    if len(cols) == 0:
        return np.zeros((n, 0, 3)), {"attempts": []}
    if cols.min() < 0 or cols.max() >= n:
        raise ValueError(f"columns must be vertex indices in 0..{n - 1}")
    e = np.zeros(n)
    e[cols] = 1.0
    t = np.full(n, float(thickness))
    if margin is None:  # a vertex's load covers its faces: start two edges further out
        edge = np.linalg.norm(np.diff(part.vertices[part.edges], axis=1)[:, 0], axis=1)
        margin = first_margin(part, t, e, COLUMN_THICKNESSES) + 2 * float(np.median(edge))
    m = float(margin)
    grow = GROW if grow is None else float(grow)
    attempts = []
    while True:
        p = patch(part, e, m)
        t0 = time.perf_counter()
        where = np.full(n, -1)
        where[p.vertices] = np.arange(len(p.vertices))
        g = compliance(
            p.part,
            t[p.vertices],
            res,
            material,
            options,
            columns=where[cols],
            progress=progress,
            tissue=tissue,
            phenotype=phenotype,
        )
        mag = np.linalg.norm(g, axis=-1)  # (n_p, k)
        moved = (
            0.0
            if p.whole or len(p.ring) == 0
            else float((mag[p.ring].max(0) / np.maximum(mag.max(0), 1e-300)).max())
        )
        attempts.append(
            {
                "margin_m": m,
                "vertices": int(len(p.vertices)),
                "whole": p.whole,
                "seconds": time.perf_counter() - t0,
                "ring_moved": moved,
            }
        )
        if p.whole or moved <= tolerance:
            out = np.zeros((n, len(cols), 3))
            out[p.vertices] = g
            order = np.searchsorted(cols, np.asarray(columns, dtype=np.int64))
            return out[:, order], {
                "margin_m": m,
                "vertices": int(len(p.vertices)),
                "attempts": attempts,
            }
        m *= grow


STORE_VERSION = 1

_WARMED: set[str] = set()
"""The FEM set-ups whose solves' compiled code :meth:`ColumnStore.warm` loaded in this process."""


def fem_setup(config: dict) -> dict:
    """What a linear FEM of a dataset's tissue is solved with, from its ``config`` (or such a
    set-up itself): ``material``, ``resolution`` and ``solver``, and for a layered preset its
    ``tissue`` and the body's ``phenotype`` (the paper's gel carries neither, so its set-ups
    read as before).
    """
    out = {
        "material": config.get("material") or {},
        "resolution": config.get("resolution") or "reference",
        "solver": config.get("solver") or {},
    }
    tissue = config.get("tissue") or "paper"
    if tissue != "paper":
        body = config.get("body") or {}
        out["tissue"] = tissue
        out["phenotype"] = config.get("phenotype", body.get("phenotype"))
    return out


class ColumnStore:
    """The compliance operator of one body part and FEM set-up at thickness ``levels`` (m), column
    by column as scenes ask for them (:func:`local_compliance`), kept in memory (one dense ``(N, N,
    3)`` float32 array per level used, each column contiguous) and, with ``cache``, on disk in
    stmpl's cache directory (``compliance/``), so a later process starts warm.

    ``setup``: a dataset config's ``material``, ``resolution`` and ``solver`` entries, and its
    ``tissue`` and body's ``phenotype`` where the tissue is a layered preset
    (:func:`fem_setup`).
    """

    def __init__(
        self, part: BodyPart, setup: dict, levels, cache: bool = True, progress: bool = False
    ):

        self.part = part
        self.setup = fem_setup(setup)
        self.levels = [float(x) for x in levels]
        self.tissue = self.setup.get("tissue", "paper")
        self.phenotype = self.setup.get("phenotype")
        self.material = (
            material(**(self.setup["material"] or {})) if self.tissue == "paper" else None
        )
        self.options = SolverOptions(**(self.setup["solver"] or {}))
        self.res = self.setup["resolution"] or "reference"
        self.cache, self.progress = cache, progress
        self._G: dict[int, np.ndarray] = {}
        self._by_column: dict[int, np.ndarray] = {}
        self._done: dict[int, np.ndarray] = {}
        self.log: list[dict] = []
        h = hashlib.sha256(
            json.dumps([STORE_VERSION, self.setup, COLUMN_TOLERANCE], sort_keys=True).encode()
        )
        for k in ("vertices", "faces"):
            h.update(np.ascontiguousarray(getattr(part, k)).tobytes())
        self.key = h.hexdigest()[:16]

    def level(self, thickness: float) -> int:
        """The index of the level at ``thickness`` (m), added if the store has none there (its
        columns are solved when asked for, like any other's).
        """
        t = float(thickness)
        if not (np.isfinite(t) and t > 0):
            raise ValueError(f"a level must be a positive thickness, got {t!r} m")
        for k, x in enumerate(self.levels):
            if abs(x - t) <= 1e-9:
                return k
        self.levels.append(t)
        return len(self.levels) - 1

    def path(self, level: int) -> pathlib.Path:
        """The disk cache file of level ``level`` (an index into ``levels``)."""
        mm = f"{self.levels[level] * 1e3:.6g}"
        return default_cache_dir() / "compliance" / f"{self.part.name}-{self.key}-{mm}mm.npz"

    def _level(self, level: int) -> tuple[np.ndarray, np.ndarray]:
        if level not in self._G:
            n = self.part.n_vertices
            self._by_column[level] = np.zeros((n, n, 3), np.float32)  # [column, vertex, xyz]
            self._G[level] = self._by_column[level].transpose(1, 0, 2)  # the same memory
            self._done[level] = np.zeros(n, bool)
            self._read(level)
        return self._G[level], self._done[level]

    def _read(self, level: int) -> None:
        """Take the columns the level's cache file holds that memory does not (another process
        may have added some since).
        """
        G, done = self._G[level], self._done[level]
        path = self.path(level)
        if not (self.cache and path.is_file()):
            return
        n = self.part.n_vertices
        try:
            with np.load(path) as z:
                cols, vals = z["columns"], z["values"]
            if vals.shape == (n, len(cols), 3) and (cols.size == 0 or cols.max() < n):
                new = ~done[cols]
                G[:, cols[new]] = vals[:, new]
                done[cols[new]] = True
        except (OSError, ValueError, KeyError):
            pass  # a broken cache file is recomputed

    @property
    def computed(self) -> int:
        """How many columns (over the levels in memory) are computed."""
        return int(sum(int(d.sum()) for d in self._done.values()))

    def missing(self, level: int, columns) -> np.ndarray:
        """The vertices of ``columns`` whose column at ``level`` is not yet computed."""
        _, done = self._level(level)
        cols = np.unique(np.asarray(columns, dtype=np.int64))
        return cols[~done[cols]]

    def warm(self) -> float:
        """Solve a few columns of a tiny flat patch with this store's FEM set-up, so that the
        compiled code every solve runs (the assembly kernel of its laws, the block products of
        the refinement) is loaded now, in the caller's thread. The first call of a compiled
        kernel in a process holds Python's GIL for some tenths of a second while Numba loads it;
        done by a solve in a background thread, that is a press answered that much later.
        Returns the seconds it took (0 where a store of the same set-up was warmed in this
        process).
        """
        setup = json.dumps(self.setup, sort_keys=True)
        if setup in _WARMED:
            return 0.0
        t0 = time.perf_counter()
        tiny = quarter_disk(np.linspace(0.0, 0.02, 5))  # 25 vertices, 2 cm
        thickness = self.levels[0] if self.levels else 0.0075
        compliance(
            tiny,
            thickness,
            self.res,
            self.material,
            self.options,
            columns=np.arange(BLOCK),
            tissue=self.tissue,
            phenotype=self.phenotype,
        )
        _WARMED.add(setup)
        return time.perf_counter() - t0

    def ensure(self, level: int, columns, save: bool = True, progress=None) -> int:
        """Compute the missing ``columns`` at ``level`` (one patch around all of them); with
        ``save``, write the level's cache file if anything was computed. Returns how many.
        ``progress``: a callable taking the number of columns solved (:func:`local_compliance`).
        """
        G, done = self._level(level)
        todo = self.missing(level, columns)
        if len(todo) == 0:
            return 0
        t0 = time.perf_counter()
        g, info = local_compliance(
            self.part,
            self.levels[level],
            todo,
            self.res,
            self.material,
            self.options,
            progress=progress,
            tissue=self.tissue,
            phenotype=self.phenotype,
        )
        if not np.all(np.isfinite(g)):
            raise ArithmeticError("the compliance operator has non-finite entries")
        G[:, todo] = g
        done[todo] = True
        self.log.append(
            {
                "level_mm": self.levels[level] * 1e3,
                "columns": int(len(todo)),
                "seconds": time.perf_counter() - t0,
                **info,
            }
        )
        if save:
            self.save(level)
        return len(todo)

    def save(self, level: int | None = None) -> None:
        """Write the computed columns of ``level`` (all levels in memory if None) to disk."""
        if not self.cache:
            return
        for lv in [level] if level is not None else list(self._G):
            G, done = self._level(lv)
            self._read(lv)  # keep what other processes added
            cols = np.flatnonzero(done)
            atomic_savez(self.path(lv), {"columns": cols, "values": G[:, cols]})

    def columns(self, level: int, columns, ensure: bool = True) -> np.ndarray:
        """``(N, k, 3)`` float32 columns at ``level`` for the vertices ``columns`` ``(k,)``,
        computed first where missing (``ensure=False``: the caller has made sure).
        """
        if ensure:
            self.ensure(level, columns)
        self._level(level)  # each column contiguous: the gather is k copies
        return self._by_column[level][np.asarray(columns, dtype=np.int64)].transpose(1, 0, 2)

    def combination(self, level: int, columns, weights) -> np.ndarray:
        """``(N, 3)`` float32: ``sum_k weights_k G[:, columns_k]`` at ``level``, the answer to
        forces ``weights`` ``(k,)`` N on the vertices ``columns`` ``(k,)`` (computed already:
        :meth:`ensure`). One product over the columns' contiguous rows.
        """
        self._level(level)
        n = self.part.n_vertices
        rows = self._by_column[level].reshape(n, 3 * n)
        w = np.asarray(weights, dtype=np.float32)
        return (w @ rows[np.asarray(columns, dtype=np.int64)]).reshape(n, 3)
