"""The subgraph a GNN answer at fidelity ``auto`` runs on, two ways: a compiled kernel (Numba;
one pass per scene, no temporary over the whole mesh) and its NumPy twin, used without Numba and
to check the kernel.

Given per scene the vertices the load moves (loaded, or moved by the linear prior by more than a
share of its deepest: :func:`stmpl.reach.moving`), the region is those grown by a ring, and
every vertex within ``steps`` more rings of it is a node. Nodes come sorted by their rings from
the region (level 0 first), then by id; the edges a step reads (those into nodes under ``steps``
rings) come target by target in that order, so that step ``s`` updates only the first nodes
over the first edges (:meth:`models.gnn.network.MeshGraphNet.forward`'s ``sizes``).

Vertex ids over a batch are ``b N + i``; edges of the mesh are the predictor's directed edges
``(2, 2E)``, and a kept edge's row among the batch's encoded edges is ``b 2E + e``.
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import numpy as np

from stmpl import reach
from stmpl.jit import loaded as numba_loaded
from stmpl.jit import njit


class Subgraph(NamedTuple):
    """The nodes and edges of a batch's subgraphs, in the order the network's steps read."""

    nodes: np.ndarray
    """``(V,)`` ids ``b N + i`` sorted by level, then id."""
    counts: np.ndarray
    """``(steps + 1,)`` nodes per level."""
    edges: np.ndarray
    """``(2, M)`` source and target, as positions in :attr:`nodes`."""
    rows: np.ndarray
    """``(M,)`` each edge's row among the batch's encoded edges, ``b 2E + e``."""
    edge_counts: np.ndarray
    """``(steps + 1,)`` edges per level of their target."""

    def sizes(self, steps: int) -> list[tuple[int, int]]:
        """Per step ``(nodes, edges)`` it updates and reads: those within ``steps - s`` rings."""
        return [
            (int(self.counts[: steps - s + 1].sum()), int(self.edge_counts[: steps - s + 1].sum()))
            for s in range(1, steps + 1)
        ]


class Mesh(NamedTuple):
    """A mesh's arrays the subgraph reads, made once per predictor (:func:`mesh`)."""

    ptr: np.ndarray  # (N + 1,) the vertex adjacency, CSR
    nbr: np.ndarray  # (2E,)
    in_ptr: np.ndarray  # (N + 1,) directed edges grouped by target
    in_order: np.ndarray  # (2E,) edge ids, target by target
    src: np.ndarray  # (2E,) each directed edge's source


def mesh(part, edge_index: np.ndarray) -> Mesh:
    """The arrays of ``part``'s mesh with directed edges ``edge_index`` ``(2, 2E)`` (source,
    target).
    """
    adj = part.adjacency.tocsr()
    n = part.n_vertices
    order = np.argsort(edge_index[1], kind="stable")
    in_ptr = np.concatenate([[0], np.cumsum(np.bincount(edge_index[1], minlength=n))])
    return Mesh(
        adj.indptr.astype(np.int64),
        adj.indices.astype(np.int64),
        in_ptr.astype(np.int64),
        order.astype(np.int64),
        np.ascontiguousarray(edge_index[0], dtype=np.int64),
    )


def subgraph(m: Mesh, part, seeds: np.ndarray, steps: int, grow: int = 0, kernel=None) -> Subgraph:
    """The subgraph of the scenes whose regions are ``seeds`` ``(B, N)`` bool grown by ``grow``
    rings. ``kernel``: :func:`compiled`'s (default), or ``False`` for the NumPy path.
    """
    seeds = np.ascontiguousarray(seeds, dtype=np.bool_)
    kernel = compiled() if kernel is None else kernel
    if kernel is False:
        return subgraph_numpy(m, part, seeds, steps, grow)
    return Subgraph(*kernel(m.ptr, m.nbr, m.in_ptr, m.in_order, m.src, seeds, steps, grow))


def subgraph_numpy(m: Mesh, part, seeds: np.ndarray, steps: int, grow: int = 0) -> Subgraph:
    """:func:`subgraph` with NumPy: rings by sparse products (:func:`stmpl.reach.hops`)."""
    B, N = seeds.shape
    region = reach.grown(part, seeds, grow) if grow else seeds
    level = reach.hops(part, region, steps).ravel()
    sub = np.flatnonzero(level <= steps)
    nodes = sub[np.argsort(level[sub], kind="stable")]
    counts = np.bincount(level[nodes], minlength=steps + 1)
    where = np.full(B * N, -1)
    where[nodes] = np.arange(len(nodes))
    targets = nodes[: int(counts[:steps].sum())]
    scene, i = np.divmod(targets, N)
    start, deg = m.in_ptr[i], m.in_ptr[i + 1] - m.in_ptr[i]
    at = np.repeat(start - np.cumsum(deg) + deg, deg) + np.arange(int(deg.sum()))
    e = m.in_order[at]
    src = m.src[e] + np.repeat(scene * N, deg)
    edges = np.stack([where[src], np.repeat(where[targets], deg)])
    rows = np.repeat(scene, deg) * len(m.src) + e
    edge_counts = np.bincount(np.repeat(level[targets], deg), minlength=steps + 1)
    return Subgraph(nodes, counts, edges, rows, edge_counts)


def _levels(ptr, nbr, seeds, steps, grow):  # pragma: no cover - compiled
    """``(B N,)`` each vertex's level: breadth first from ``seeds`` ``(B, N)``, the first
    ``grow`` rings level 0 (the region), then 1 to ``steps``, ``steps + 2`` beyond.
    """
    B, N = seeds.shape
    far = steps + 2
    level = np.full(B * N, far, np.int64)
    queue = np.empty(B * N, np.int64)
    dist = np.empty(B * N, np.int64)
    for b in range(B):
        head, tail = 0, 0
        for i in range(N):
            if seeds[b, i]:
                level[b * N + i] = 0
                dist[b * N + i] = 0
                queue[tail] = b * N + i
                tail += 1
        while head < tail:
            v = queue[head]
            head += 1
            d = dist[v]
            if d >= steps + grow:
                continue
            i = v - b * N
            for k in range(ptr[i], ptr[i + 1]):
                w = b * N + nbr[k]
                if level[w] == far:
                    dist[w] = d + 1
                    level[w] = max(d + 1 - grow, 0)
                    queue[tail] = w
                    tail += 1
    return level


def _ordered(level, in_ptr, in_order, src, steps, N):  # pragma: no cover - compiled
    """The :class:`Subgraph`'s arrays from each vertex's ``level`` (:func:`_levels`)."""
    E = len(src)
    counts = np.zeros(steps + 1, np.int64)
    for v in range(len(level)):
        if level[v] <= steps:
            counts[level[v]] += 1
    fill = np.zeros(steps + 1, np.int64)
    for s in range(steps):
        fill[s + 1] = fill[s] + counts[s]
    nodes = np.empty(counts.sum(), np.int64)
    where = np.full(len(level), -1, np.int64)
    for v in range(len(level)):  # by level, then by id
        s = level[v]
        if s <= steps:
            nodes[fill[s]] = v
            where[v] = fill[s]
            fill[s] += 1
    targets = counts[:steps].sum()  # the nodes under ``steps`` rings
    M = 0
    for p in range(targets):
        i = nodes[p] % N
        M += in_ptr[i + 1] - in_ptr[i]
    edges = np.empty((2, M), np.int64)
    rows = np.empty(M, np.int64)
    edge_counts = np.zeros(steps + 1, np.int64)
    q = 0
    for p in range(targets):
        b, i = nodes[p] // N, nodes[p] % N
        for k in range(in_ptr[i], in_ptr[i + 1]):
            e = in_order[k]
            edges[0, q] = where[b * N + src[e]]
            edges[1, q] = p
            rows[q] = b * E + e
            q += 1
        edge_counts[level[nodes[p]]] += in_ptr[i + 1] - in_ptr[i]
    return nodes, counts, edges, rows, edge_counts


def make_kernel():
    """The compiled :func:`subgraph`: ``kernel(ptr, nbr, in_ptr, in_order, src, seeds, steps,
    grow)`` returns the :class:`Subgraph`'s arrays; ``False`` when Numba is absent.
    """
    jit = njit()
    if jit is None:
        return False
    levels, ordered = jit(_levels), jit(_ordered)

    def kernel(ptr, nbr, in_ptr, in_order, src, seeds, steps, grow):
        level = levels(ptr, nbr, seeds, steps, grow)
        return ordered(level, in_ptr, in_order, src, steps, seeds.shape[1])

    return kernel


@functools.cache
def compiled():
    """The compiled kernel (importing Numba and loading the kernel from its cache: about half a
    second in a new process, once).
    """
    return make_kernel()


def loaded():
    """:func:`compiled`'s kernel if Numba is already imported in this process (by the FEM, or by
    :meth:`~models.gnn.predictor.GNNPredictor.compile`), else ``False``: a one-off answer does
    not pay half a second to save a third of a millisecond.
    """
    return compiled() if numba_loaded() else False
