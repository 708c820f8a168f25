"""The skin held where an object holds it, and the rest answered by the linear FEM.

A grip's fingers drag the skin under them along with their sweep, and on the layered forearm
the stiff skin over soft fat carries that drag along the whole limb: most of a grip's
displacement lies centimetres from any contact, where the strains are small. There the tissue
is linear: held at the FEM's own displacement within 2 cm of the contact, the rest of the
skin as the linear FEM answers it lies within 0.14-0.55 % of the peak displacement on average
(``benchmarks/grip_far_field.py``). So what happens near the object (large strains, contact,
friction) and what the tissue carries away from it (linear) can be answered apart.

:class:`Holding` is the linear FEM of a tissue on a part: its stiffness at rest
(:func:`fem.simulate.tissue_mesh`, the tangent of its laws at no strain), factorised once. The
skin's vertices ``H`` held at displacements ``u_H`` and every other node free of load, the
skin's displacement is

    u = G[:, H] G[H, H]^-1 u_H

with ``G`` the 3D nodal compliance: ``G[i, j]`` the displacement of vertex ``i`` under a unit
force on vertex ``j`` (3 x 3 per pair). Its columns at the held vertices are solved with the one
factorisation (a block of right-hand sides), so holding other vertices needs no new one.
"""

from __future__ import annotations

import functools
import hashlib
import json
import pathlib

import numpy as np
import scipy.linalg
import scipy.linalg.lapack
from tqdm import tqdm

from fem.closure import CONTACT_RULE, HeldColumns, closure_forces
from fem.columns import Quantized, product
from fem.finer import FinerPart, meshed
from fem.friction import SKIN_FRICTION
from fem.shapes import ROUNDING
from fem.simulate import resolution, tissue_mesh
from fem.solver import Solver
from stmpl import jit
from stmpl.body.model import default_cache_dir
from stmpl.files import atomic_savez
from stmpl.part import BodyPart
from stmpl.pose import within_reach

HOLD_RESOLUTION = {"subdivisions": 0, "layers": 1, "order": 2}
"""The held skin's linear FEM: the tissue's element layers in quadratic elements on the plain
part (a part subdivided once is meshed on the part it came from, whose nodes carry its
vertices): about 60k unknowns on the forearm, factorised in some 5 s."""

STORE_VERSION = 1
"""Bumped when what a cached compliance file holds changes meaning."""

BLOCK = 100
"""Vertices whose columns are solved in one block of right-hand sides."""

CACHED_HOLDS = 256
"""Factorised holds (one per distinct held set and thickness) a :class:`HeldSkin` keeps in
memory; a training set's samples each have one (1-10 MB a sample on the forearm's grips)."""

CACHED_CLOSURES = 1024
"""Closures (:meth:`HeldSkin.closed`, 75 kB each on the forearm: the displacement and the
contact forces) a :class:`HeldSkin` keeps."""


class Holding:
    """The linear FEM of ``tissue`` (a preset of :mod:`fem.layers`, or ``"paper"``) on
    ``part`` with skin and fat ``thickness`` (m, scalar or ``(N,)``), at resolution ``res``
    (quadratic elements: a part subdivided once is meshed on the part it came from, whose
    nodes carry its vertices, :mod:`fem.finer`), factorised at rest. ``phenotype`` shapes a
    layered preset's layers.
    """

    def __init__(
        self,
        part: BodyPart,
        thickness,
        res=HOLD_RESOLUTION,
        tissue: str = "forearm",
        phenotype: dict | None = None,
    ):
        n = part.n_vertices
        t = np.broadcast_to(np.asarray(thickness, dtype=float), (n,)).copy()
        if not (np.isfinite(t).all() and (t > 0).all()):
            raise ValueError("thickness must be finite and positive (m) at every vertex")
        r = resolution(res)
        if r.order != 2:
            raise ValueError(
                f"the held skin is answered in quadratic elements, got order {r.order}"
            )
        meshed_part, meshed_t = meshed(part, t, r.order)
        mesh, material = tissue_mesh(meshed_part, meshed_t, r, tissue, phenotype)
        self.solver = Solver(mesh, material, order=r.order)
        u0 = np.zeros((self.solver.n_all, 3))
        _, K = self.solver.assemble(u0, u0)
        self.solver.linear.factor(K)
        self.part = part
        self.nodes = FinerPart(self.solver, part).nodes  # (N,) the node at each vertex
        self._row = np.full(self.solver.n_all * 3, -1)
        self._row[self.solver.free] = np.arange(len(self.solver.free))

    @property
    def free(self) -> np.ndarray:
        """``(N,)`` bool: the vertices that can move (the others lie on the mesh's fixed rim)."""
        return self._row[self.nodes * 3] >= 0

    @property
    def unknowns(self) -> int:
        """The linear FEM's free degrees of freedom."""
        return len(self.solver.free)

    def columns(self, vertices) -> np.ndarray:
        """``(3 N, 3 k)`` m/N: the skin's displacement (vertex by vertex, x y z) under a unit
        force along x, y and z on each of ``vertices`` ``(k,)`` in turn.
        """
        v = np.asarray(vertices, dtype=np.int64)
        rows = self._row[(self.nodes[v][:, None] * 3 + np.arange(3)).ravel()]
        if (rows < 0).any():
            k = int(v[np.argmax((rows < 0).reshape(-1, 3).any(1))])
            raise ValueError(f"vertex {k} is held by the mesh itself (a fixed rim): it moves not")
        B = np.zeros((len(self.solver.free), len(rows)), order="F")
        B[rows, np.arange(len(rows))] = 1.0
        X = np.zeros((self.solver.n_all * 3, len(rows)))
        X[self.solver.free] = self.solver.linear.solve(B)
        return X.reshape(self.solver.n_all, 3, -1)[self.nodes].reshape(3 * len(self.nodes), -1)

    def answer(self, held, displacement) -> np.ndarray:
        """``(N, 3)`` m: the skin's displacement with the vertices ``held`` ``(k,)`` at
        ``displacement[held]`` (``displacement`` ``(N, 3)`` m; its other rows are not read)
        and no load elsewhere.
        """
        n = self.part.n_vertices
        h = np.unique(np.asarray(held, dtype=np.int64))
        if len(h) == 0:
            raise ValueError("no vertex is held: the linear FEM's answer would be the rest")
        if h.min() < 0 or h.max() >= n:
            raise ValueError(f"held vertices must be indices in 0..{n - 1}")
        u = np.asarray(displacement, dtype=float)
        if u.shape != (n, 3):
            raise ValueError(f"displacement must be (N, 3) = {(n, 3)}, got {u.shape}")
        if not np.isfinite(u[h]).all():
            raise ValueError("the held displacement is not finite")
        G = self.columns(h)
        at = (h[:, None] * 3 + np.arange(3)).ravel()
        forces = np.linalg.solve(G[at], u[h].ravel())
        return (G @ forces).reshape(n, 3)


class SkinCompliance:
    """The skin's 3D nodal compliance ``G`` ``(3 N, 3 N)`` (m/N, float32; vertex by vertex, x y
    z) of ``tissue`` on ``part`` with skin and fat ``thickness`` (m, ``(N,)``): the linear FEM
    at rest (:class:`Holding`), solved column block by column block as they are asked for and
    kept in memory and, with ``cache``, in stmpl's cache directory (``holding/``), so a later
    process starts warm. The fixed rim's vertices have zero columns and rows.

    A held answer needs ``G``'s columns at the held vertices; a model that holds the skin near
    the objects (:mod:`models.holding`) asks for those of every vertex near an object of its
    scenes. ``G`` is kept column by column (Fortran order), so the columns of a few hundred
    vertices are read as contiguous blocks (a held answer's product on the forearm in 3 ms,
    not 66 ms gathered across the rows). The whole of ``G`` on the forearm's 2109 vertices is
    160 MB and some 6k solves.
    """

    def __init__(
        self,
        part: BodyPart,
        thickness,
        tissue: str = "forearm",
        phenotype: dict | None = None,
        cache: bool = True,
    ):
        n = part.n_vertices
        t = np.broadcast_to(np.asarray(thickness, dtype=float), (n,)).copy()
        if not (np.isfinite(t).all() and (t > 0).all()):
            raise ValueError("thickness must be finite and positive (m) at every vertex")
        self.part, self.thickness, self.tissue, self.phenotype = part, t, tissue, phenotype
        self.cache = cache
        h = hashlib.sha256(
            json.dumps([STORE_VERSION, HOLD_RESOLUTION, tissue, phenotype], sort_keys=True).encode()
        )
        for a in (part.vertices, part.faces, t.astype(np.float32)):
            h.update(np.ascontiguousarray(a).tobytes())
        self.key = h.hexdigest()[:16]
        self.G = np.zeros((3 * n, 3 * n), np.float32, order="F")  # column by column
        self.done = np.zeros(n, bool)
        self.quantized = Quantized(self.G)  # the products' 16-bit columns, made as read
        self._holding: Holding | None = None
        self._free: np.ndarray | None = None
        self._read()

    @property
    def path(self) -> pathlib.Path:
        """The disk cache file: the columns and which are solved, in one file (written whole
        and atomically, so a column read from it is always one that was solved).
        """
        return default_cache_dir() / "holding" / f"{self.part.name}-{self.key}.npz"

    @property
    def holding(self) -> Holding:
        """The factorised linear FEM (made when a column is first solved)."""
        if self._holding is None:
            self._holding = Holding(
                self.part, self.thickness, HOLD_RESOLUTION, self.tissue, self.phenotype
            )
            self._free = self._holding.free
        return self._holding

    def _read(self) -> None:
        if not (self.cache and self.path.is_file()):
            return
        try:
            with np.load(self.path) as z:
                G, done, free = z["G"], z["done"], z["free"]
            if G.shape != self.G.shape or done.shape != self.done.shape:
                return
            self.G[:] = G
            self.done[:] = done
            self.quantized.forget(np.arange(3 * len(done)))
            self._free = free
        except (OSError, ValueError, KeyError):
            pass  # a broken cache file is solved again

    def _write(self) -> None:
        if self.cache:
            atomic_savez(self.path, {"G": self.G, "done": self.done, "free": self.free})

    @property
    def free(self) -> np.ndarray:
        """``(N,)`` bool: the vertices that can move (not on the fixed rim)."""
        if self._free is None:
            self._free = self.holding.free
        return self._free

    def missing(self, vertices) -> np.ndarray:
        """The free vertices of ``vertices`` whose columns are not yet solved."""
        v = np.unique(np.asarray(vertices, dtype=np.int64))
        return v[~self.done[v] & self.free[v]]

    def solve(self, vertices, progress: bool = False) -> int:
        """Solve the columns of ``vertices`` not yet solved (blocks of :data:`BLOCK`, a progress
        bar with ``progress``), write the cache, and return how many were solved.
        """
        todo = self.missing(vertices)
        if len(todo) == 0:
            return 0
        blocks = np.array_split(todo, -(-len(todo) // BLOCK))
        bar = tqdm(total=len(todo), desc="skin compliance", unit="vertex", disable=not progress)
        for b in blocks:
            at = (b[:, None] * 3 + np.arange(3)).ravel()
            self.G[:, at] = self.holding.columns(b)
            self.quantized.forget(at)
            self.done[b] = True
            bar.update(len(b))
        bar.close()
        self._write()
        return len(todo)

    def product(self, at: np.ndarray, f: np.ndarray, bits: int = 32) -> np.ndarray:
        """``(3 N,)`` float32: ``G[:, at] @ f``, the skin's displacement (m) under forces ``f``
        ``(len(at),)`` (N) on the DOFs ``at`` (their columns solved), read in place where Numba
        is loaded (:mod:`fem.columns`). ``bits=16``: from the columns' 16-bit copy where Numba
        is loaded (half the bytes; for forces that do not cancel, a model's own: within
        ``sum |f_j| s_j / 2`` of the float32 product, ``s_j`` a column's largest entry over
        32767), float32 otherwise.
        """
        if bits not in (16, 32):
            raise ValueError(f"a product reads the columns in 16 or 32 bits, got {bits!r}")
        at = np.asarray(at, dtype=np.int64)
        if bits == 16 and jit.loaded():
            return self.quantized.product(at, f)
        return product(self.G, at, f)

    def columns(self, vertices) -> np.ndarray:
        """``(3 N, 3 k)`` the columns of ``vertices`` ``(k,)`` (free ones; solved if missing)."""
        v = np.asarray(vertices, dtype=np.int64)
        if not self.free[v].all():
            k = int(v[np.argmin(self.free[v])])
            raise ValueError(f"vertex {k} is held by the mesh itself (a fixed rim): it moves not")
        self.solve(v)
        return self.G[:, (v[:, None] * 3 + np.arange(3)).ravel()]


class HeldSkin:
    """The skin of ``part`` held near the objects of a pose and answered elsewhere by the linear
    FEM of ``tissue`` (a layered preset's name, with the body's ``phenotype``), at any
    thickness (one :class:`SkinCompliance` each): the held vertices are the free ones within
    reach of an object (:func:`stmpl.pose.within_reach`), and the skin held at ``r`` there is

        u = G[:, H] G[H, H]^-1 r_H

    (:meth:`answer`; the learned models' held prior, :mod:`models.holding`, answers the same in
    torch). ``G[H, H]``'s Cholesky factor is kept for each held set met.
    """

    def __init__(self, part: BodyPart, tissue: str, phenotype: dict | None = None):
        self.part, self.tissue, self.phenotype = part, tissue, phenotype
        self._stores: dict[bytes, SkinCompliance] = {}
        self._holds: dict[tuple, tuple] = {}
        self._closures: dict[tuple, np.ndarray] = {}

    def store(self, thickness) -> tuple[bytes, SkinCompliance]:
        """The compliance of the skin at ``thickness`` ``(N,)`` (m), and its key."""
        t = np.asarray(thickness, dtype=np.float32)
        key = t.tobytes()
        if key not in self._stores:
            self._stores[key] = SkinCompliance(self.part, t, self.tissue, self.phenotype)
        return key, self._stores[key]

    def held(self, gap, thickness) -> np.ndarray:
        """``(k,)`` the vertices a sample with ``gap`` ``(N,)`` (m) and ``thickness`` holds."""
        _, s = self.store(thickness)
        return np.flatnonzero(within_reach(gap) & s.free)

    def prepare(self, gaps, thicknesses, progress: bool = True) -> int:
        """Solve the columns every sample (``gaps``, ``thicknesses`` ``(B, N)``, m) holds, one
        store per thickness; returns how many were solved (0: all cached).
        """
        by: dict[bytes, list] = {}
        for g, t in zip(np.asarray(gaps), np.asarray(thicknesses)):
            key, _ = self.store(t)
            by.setdefault(key, []).append(g)
        n = 0
        for key, gs in by.items():
            s = self._stores[key]
            n += s.solve(np.flatnonzero(within_reach(np.stack(gs)).any(0) & s.free), progress)
        return n

    def hold(self, gap, thickness) -> tuple[SkinCompliance, np.ndarray, np.ndarray]:
        """A sample's store, its held DOFs ``(3 k,)`` (vertex by vertex, x y z) and the lower
        Cholesky factor of ``G[H, H]`` ``(3 k, 3 k)`` (:func:`held_factor`; kept); no DOFs where
        no object is near.
        """
        key, s = self.store(thickness)
        H = np.flatnonzero(within_reach(gap) & s.free)
        k = (key, H.tobytes())
        if k not in self._holds:
            s.solve(H)
            at = (H[:, None] * 3 + np.arange(3)).ravel()
            L = held_factor(s.G, at)
            if len(self._holds) >= CACHED_HOLDS:
                self._holds.pop(next(iter(self._holds)))
            self._holds[k] = (at, L)
        return (s, *self._holds[k])

    def pushing(self, gap, thickness) -> tuple[SkinCompliance, np.ndarray, np.ndarray]:
        """A sample's store, its held DOFs ``(3 k,)`` (as :meth:`hold`) and the compliance's
        diagonal there ``(3 k,)`` (m/N, float64): what :meth:`push` reads, no factor.
        """
        key, s = self.store(thickness)
        H = np.flatnonzero(within_reach(gap) & s.free)
        s.solve(H)
        at = (H[:, None] * 3 + np.arange(3)).ravel()
        return s, at, s.G[at, at].astype(np.float64)

    def push(self, r, forces, gap, thickness) -> np.ndarray:
        """``(N, 3)`` in the units of ``r`` and ``forces`` ``(N, 3)``: the skin moved by ``r``
        on the held vertices of a sample with ``gap`` and ``thickness`` ``(N,)`` (m), and
        everywhere by the forces ``forces_H / (d_H PUSH_SPREAD)`` on the held DOFs, ``d`` the
        compliance's diagonal there (:data:`PUSH_SPREAD`), carried by the compliance; zero
        where no object is near. No factor: what the skin does beyond the held vertices comes
        of the forces alone.
        """
        s, at, d = self.pushing(gap, thickness)
        r = np.asarray(r)
        if len(at) == 0:
            return np.zeros_like(r)
        f = (np.asarray(forces).reshape(-1)[at] / (d * PUSH_SPREAD)).astype(np.float32)
        u = s.product(at, f, bits=16).astype(np.float64)
        u[at] += r.reshape(-1)[at]
        return u.reshape(r.shape).astype(r.dtype)

    def closure(
        self,
        gap,
        way,
        thickness,
        friction: float = SKIN_FRICTION,
        rounding: float = ROUNDING,
        rule: str = CONTACT_RULE,
    ) -> np.ndarray:
        """``(N, 3)`` m, float32: the skin's displacement as the objects of a pose close on it
        (:meth:`closed`, which gives the contact forces beside it).
        """
        return self.closed(gap, way, thickness, friction, rounding, rule)[0]

    def closed(
        self,
        gap,
        way,
        thickness,
        friction: float = SKIN_FRICTION,
        rounding: float = ROUNDING,
        rule: str = CONTACT_RULE,
    ) -> tuple[np.ndarray, np.ndarray]:
        """``(u, f)``: the skin's displacement ``u`` ``(N, 3)`` (m, float32) as the objects of
        a pose (``gap`` ``(N,)`` m, ``way`` ``(N, 3)`` m per m) close on it with Coulomb's
        ``friction``, at ``thickness`` ``(N,)`` (m), answered by the linear FEM
        (:mod:`fem.closure`, its contact on the held vertices), and the contact force ``f``
        ``(N, 3)`` (N, float64) the objects put on each vertex; both zero where no object is
        near. ``rounding`` (m): how far outside the objects' faces the FEM's surface stands (a
        mesh's, :data:`fem.shapes.ROUNDING`; none for the analytic ball and disk of a dataset's
        presses). ``rule``: how each step's contact settles (:data:`fem.closure.CONTACT_RULES`).
        Kept for the next call with the same pose (a training set's samples come again every
        epoch); both arrays are read-only.
        """
        g = np.asarray(gap, dtype=np.float64)
        w = np.asarray(way, dtype=np.float64)
        if w.shape != (len(g), 3):
            raise ValueError(f"way must be (N, 3) = {(len(g), 3)}, got {w.shape}")
        key, s = self.store(thickness)
        k = (key, g.tobytes(), w.tobytes(), float(friction), float(rounding), rule)
        if k not in self._closures:
            H = np.flatnonzero(within_reach(g) & s.free)
            out = np.zeros((len(g), 3), np.float32)
            forces = np.zeros((len(g), 3))
            if len(H):
                s.solve(H)
                at = (H[:, None] * 3 + np.arange(3)).ravel()
                n = self.part.normals[H]
                G = HeldColumns(s.G, at)  # read as the contact reaches a vertex
                f = closure_forces(G, n, g[H], w[H], friction, rounding=rounding, rule=rule)
                pushed = np.flatnonzero(f.any(1))  # the skin the objects push: a few vertices
                cols = (H[pushed][:, None] * 3 + np.arange(3)).ravel()
                out = (s.G[:, cols] @ f[pushed].ravel().astype(np.float32)).reshape(-1, 3)
                forces[H] = f
            if len(self._closures) >= CACHED_CLOSURES:
                self._closures.pop(next(iter(self._closures)))
            out.flags.writeable = False
            forces.flags.writeable = False
            self._closures[k] = (out, forces)
        return self._closures[k]

    def forget_closures(self) -> None:
        """Forget the closures kept (:meth:`closed`); the compliance and the holds stay."""
        self._closures.clear()

    def forget_poses(self) -> None:
        """Forget what was kept of the poses met: their closures and the factors of their held
        sets (:meth:`hold`; a held set is a pose's own, so a moving object meets a new one at
        nearly every answer). The compliance, which serves every pose, stays.
        """
        self._closures.clear()
        self._holds.clear()

    def answer(self, r, gap, thickness) -> np.ndarray:
        """``(N, 3)`` the skin held at ``r`` ``(N, 3)`` (any unit) on the held vertices of a
        sample with ``gap`` and ``thickness`` ``(N,)`` (m), the linear FEM's answer elsewhere;
        zero where no object is near.
        """
        s, at, L = self.hold(gap, thickness)
        r = np.asarray(r)
        if len(at) == 0:
            return np.zeros_like(r)
        f = scipy.linalg.cho_solve((L, True), r.reshape(-1)[at].astype(np.float64))
        return s.product(at, f).reshape(r.shape).astype(r.dtype)


PUSH_SPREAD = 25.0
"""How many times its own compliance a held DOF moves under forces spread evenly over a grip's
held set (the held block's row sums over its diagonal on the forearm's test grips: 17-32 in
the median): :meth:`HeldSkin.push` divides by it, so that an even answer moves the skin by
about itself."""

HELD_FACTOR_CONDITION = 1e5
"""A held block is factorised in float32 where its condition number (in the 1-norm, estimated
from the factor by LAPACK's ``spocon``) is below this: its solve then lies within
``HELD_FACTOR_CONDITION`` times float32's rounding of the float64 one, the same bound the
float32 compliance the block is read from puts on either. The forearm's grips: 5e3-3e4."""


def held_factor(G: np.ndarray, at: np.ndarray) -> np.ndarray:
    """The lower Cholesky factor of the held block ``G[at, at]`` (:func:`held_block`; where
    Numba is loaded, its lower triangle read in place) of the compliance ``G`` ``(3 N, 3 N)``
    (m/N, float32) on the held DOFs ``at`` ``(k,)``: in float32 where that factorisation
    succeeds and the block's condition number is below :data:`HELD_FACTOR_CONDITION` (half the
    time and memory of float64; on the forearm's test grips the answers move by at most 3.5e-6
    of their peak). Else in float64, and where even that meets a non-positive pivot (the
    float32 compliance's rounding of a nearly singular block), with ``1e-7`` of the mean
    diagonal added to the diagonal. No held DOFs (no object near): an empty factor.
    """
    at = np.asarray(at, dtype=np.int64)
    if len(at) == 0:
        return np.zeros((0, 0), np.float32)
    A = None  # the float64 block, gathered where NumPy reads it or float32 will not do
    kernel = _block_kernel() if jit.loaded() and G.flags.f_contiguous else None
    if kernel is None:
        A = held_block(G, at)
        A32 = A.astype(np.float32)
        norm = float(np.abs(A32).sum(0).max())
    else:
        A32, norm = kernel(G, at)
    try:  # LAPACK factorises the Fortran-ordered transpose in place, from its lower triangle
        L = scipy.linalg.cholesky(A32.T, lower=True, overwrite_a=True, check_finite=False)
        rcond, info = scipy.linalg.lapack.spocon(L, norm, uplo="L")
        if info == 0 and rcond * HELD_FACTOR_CONDITION > 1.0:
            return L
    except np.linalg.LinAlgError:
        pass
    if A is None:
        A = held_block(G, at)
    try:
        return scipy.linalg.cholesky(A, lower=True)
    except np.linalg.LinAlgError:
        A[np.diag_indices_from(A)] += 1e-7 * float(A.diagonal().mean())
        return scipy.linalg.cholesky(A, lower=True)


def held_block(G: np.ndarray, at: np.ndarray) -> np.ndarray:
    """``(k, k)`` float64: ``G[at, at]`` of the compliance ``G`` ``(3 N, 3 N)`` (m/N, float32)
    on the held DOFs ``at`` ``(k,)``, made symmetric (``(A + A^T) / 2``: ``G``'s columns are
    solved apart, so its two halves differ by the solver's rounding).
    """
    A = G[:, at][at].astype(np.float64)
    return 0.5 * (A + A.T)


@functools.lru_cache(maxsize=1)
def _block_kernel():
    """The held block's lower triangle in float32 (what LAPACK reads of a symmetric matrix; the
    compliance's two triangles differ by less than float32's rounding, some 5e-9 of the
    largest entry on the forearm's grips), read in place (NumPy gathers the whole columns
    first: 14 MB for a grip's two hundred held vertices on the forearm, to keep a sixtieth of
    it), and the symmetric block's 1-norm; ``None`` without Numba. The triangle is returned as
    the upper one of a C-ordered array, whose transpose LAPACK takes without a copy.
    """
    compile_ = jit.njit(error_model="numpy")
    if compile_ is None:
        return None

    @compile_
    def block(G, at):  # pragma: no cover - compiled
        k = at.shape[0]
        B = np.zeros((k, k), np.float32)  # row j: the block's column j, from its diagonal down
        sums = np.zeros(k)
        for j in range(k):
            col = at[j]
            for i in range(j, k):
                v = G[at[i], col]
                B[j, i] = v
                sums[j] += abs(v)
                if i > j:
                    sums[i] += abs(v)
        return B, sums.max()

    return block
