"""A trained GNN answered with NumPy alone: the checkpoint's weights read as arrays, its inputs,
prior, network and outputs as :class:`models.gnn.predictor.GNNPredictor` has them, and no torch
imported. Torch's import alone takes 1-3 s on a small machine, longer than a one-off answer
(``stmpl simulate``, ``stmpl predict``) needs for everything else; training, evaluation, the
viewer and compiled or batched answers keep the torch predictor. Read through
:func:`stmpl.predictor.read` with ``engine="numpy"``; the answers equal the torch predictor's
within float32 rounding (``tests/models/test_arrays.py``).
"""

from __future__ import annotations

import functools

import numpy as np
import scipy.sparse as sp
from threadpoolctl import ThreadpoolController

from fem.compliance import ColumnStore
from fem.holding import HeldSkin
from models.features import (
    CORRECTION_SCALE,
    HOLDING,
    MIN_TOTAL_N,
    PRESSURE_LOG_MAX,
    PRESSURE_OUT_SCALE,
    gap_of,
    near_objects,
    posed_answer,
    runs_held_only,
    squeezes,
    way_channels,
)
from models.gnn.subgraph import loaded, mesh, subgraph
from models.linear.columns import (
    grown_levels,
    on_demand_answer,
    stored_answer,
    stored_matrices,
)
from models.trained import TrainedPredictor, checkpoint_part
from stmpl import checkpoint, reach
from stmpl.pose import GAP_REACH, within_reach


@functools.cache
def blas() -> ThreadpoolController:
    """The BLAS libraries loaded, whose threads an answer limits to one: products a few dozen
    columns wide gain little from a second thread on an idle machine (the default GNN at
    fidelity auto 6.3 against 6.7 ms a scene), and on a busy one the second thread waits on a
    taken core (72 ms in place of 9 with two other jobs on a 2-core machine).
    """
    return ThreadpoolController()


LAYER_NORM_EPS = 1e-5
"""torch's LayerNorm default, which the networks are trained with."""


def _layer_norm(y: np.ndarray, gamma: np.ndarray, beta: np.ndarray) -> np.ndarray:
    mean = y.mean(-1, keepdims=True)
    y = y - mean
    var = np.einsum("ij,ij->i", y, y)[:, None] / y.shape[1]
    y *= 1.0 / np.sqrt(var + LAYER_NORM_EPS)
    return y * gamma + beta


class GraphNetArrays:
    """:class:`models.gnn.network.NormalisedGraphNet`'s inference from its state dict ``state``
    (name -> float32 array, the torch names without the ``model.`` prefix).
    """

    def __init__(self, state: dict, steps: int):
        def mlp(name, norm=True):
            w = [state[f"{name}.{k}"] for k in ("0.weight", "0.bias", "2.weight", "2.bias")]
            if norm:
                w += [state[f"{name}.3.weight"], state[f"{name}.3.bias"]]
            return [np.ascontiguousarray(x.T) if x.ndim == 2 else x for x in w]

        self.node_shift, self.node_scale = state["node_norm.shift"], state["node_norm.scale"]
        self.edge_shift, self.edge_scale = state["edge_norm.shift"], state["edge_norm.scale"]
        self.node_encoder = mlp("net.node_encoder")
        self.edge_encoder = mlp("net.edge_encoder")
        self.decoder = mlp("net.decoder", norm=False)
        self.steps = []
        for s in range(steps):
            p = f"net.processor.{s}"
            W = state[f"{p}.edge_in.weight"]  # (L, 3L): [A | B | C]
            L = W.shape[0]
            self.steps.append(
                {
                    "A": np.ascontiguousarray(W[:, :L].T),
                    "BC": np.ascontiguousarray(np.concatenate([W[:, L : 2 * L], W[:, 2 * L :]]).T),
                    "b": state[f"{p}.edge_in.bias"],
                    "edge_out": [
                        np.ascontiguousarray(state[f"{p}.edge_out.1.weight"].T),
                        state[f"{p}.edge_out.1.bias"],
                        state[f"{p}.edge_out.2.weight"],
                        state[f"{p}.edge_out.2.bias"],
                    ],
                    "node": mlp(f"{p}.node_mlp"),
                }
            )

    @staticmethod
    def _mlp(x: np.ndarray, w: list) -> np.ndarray:
        y = np.maximum(x @ w[0] + w[1], 0.0)
        y = y @ w[2] + w[3]
        return _layer_norm(y, w[4], w[5]) if len(w) == 6 else y

    def encode_edges(self, edge_attr: np.ndarray) -> np.ndarray:
        """``(E, 4)`` raw edge features -> ``(E, latent)`` encoded."""
        x = ((edge_attr - self.edge_shift) / self.edge_scale).astype(np.float32)
        return self._mlp(x, self.edge_encoder)

    def __call__(self, x, e, edge_index, sizes=None) -> np.ndarray:
        """``x`` ``(V, C)`` raw node features, ``e`` ``(M, latent)`` encoded edges, ``edge_index``
        ``(2, M)`` (source, target) with the targets in rising order; ``sizes`` as
        :meth:`models.gnn.network.MeshGraphNet.forward`'s.
        """
        x = ((x - self.node_shift) / self.node_scale).astype(np.float32)
        h = self._mlp(x, self.node_encoder)
        j, i = edge_index
        for s, w in enumerate(self.steps):
            n, m = (len(h), e.shape[0]) if sizes is None else sizes[s]
            L = h.shape[1]
            bc = h @ w["BC"]  # (V, 2L): B h, C h
            z = e[:m] @ w["A"]
            z += w["b"]
            z += bc[i[:m], :L]
            z += bc[j[:m], L:]
            np.maximum(z, 0.0, out=z)
            lin, bias, gamma, beta = w["edge_out"]
            e = e[:m] + _layer_norm(z @ lin + bias, gamma, beta)
            agg = _sum_into(e, i[:m], n)
            nw = w["node"]
            y = h[:n] @ nw[0][:L] + agg @ nw[0][L:] + nw[1]
            np.maximum(y, 0.0, out=y)
            h = h[:n] + _layer_norm(y @ nw[2] + nw[3], nw[4], nw[5])
        return self._mlp(h, self.decoder)


def _sum_into(e: np.ndarray, target: np.ndarray, n: int) -> np.ndarray:
    """``(n, L)``: the rows of ``e`` summed by their ``target`` (rising), as one sparse product
    (three times faster than ``np.add.reduceat`` here, ten times ``np.add.at``).
    """
    ptr = np.zeros(n + 1, np.int64)
    np.cumsum(np.bincount(target, minlength=n), out=ptr[1:])
    ones = np.ones(len(target), e.dtype)
    return sp.csr_matrix((ones, np.arange(len(target)), ptr), shape=(n, len(target))) @ e


class ColumnPrior:
    """The linear FEM on demand (a :class:`fem.compliance.ColumnStore`) as a GNN's prior, in
    NumPy; ``exact``: a uniform layer's thickness becomes a level of its own (another body's
    prior, as its training answers were solved).
    """

    def __init__(self, store, exact: bool = False):
        self.store, self.exact = store, exact
        self.levels = np.asarray(store.levels, np.float32)

    def __call__(self, thickness: np.ndarray, force: np.ndarray) -> np.ndarray:
        self.levels = grown_levels(self.levels, thickness, True, self.exact)
        return on_demand_answer(self.store, self.levels, thickness, force)


class StoredPrior:
    """Stored columns (a checkpoint's ``prior.levels``, ``prior.index``, ``prior.values``)."""

    def __init__(self, levels, index, values, n: int):
        self.levels = np.asarray(levels, np.float32)
        self.matrices = stored_matrices(index, values, n)

    def __call__(self, thickness: np.ndarray, force: np.ndarray) -> np.ndarray:
        grown_levels(self.levels, thickness, False)  # refuses a thickness outside the levels
        return stored_answer(self.matrices, self.levels, thickness, force)


class GNNArrays(TrainedPredictor):
    """A trained :class:`~models.gnn.predictor.GNNPredictor` answered in NumPy, from its
    checkpoint (:meth:`from_checkpoint`); the same inputs, prior, fidelities, bodies, envelope
    and checks.
    """

    name = "gnn"
    poses = True

    @classmethod
    def options(cls, config: dict | None = None) -> dict:
        """A checkpoint's options as trained (the torch predictor checked them then)."""
        out = {"given": "force", **(config or {})}
        if out.get("prior", "none") not in ("none", "linear", "contact", *HOLDING):
            raise ValueError(
                f"prior must be none, linear, contact, held or closure, got {out['prior']!r}"
            )
        return out

    def __init__(self, part, config: dict, state: dict, fidelity="full", **options):
        super().__init__(part, config, fidelity, **options)
        e = part.edges
        self._ei = np.concatenate([e, e[:, ::-1]]).T  # (2, 2E): both directions, as trained
        self._mesh = mesh(part, self._ei)
        order = np.argsort(self._ei[1], kind="stable")  # the edges target by target
        self._order, self._sorted = order, np.ascontiguousarray(self._ei[:, order])
        self.steps = int(self.config["steps"])
        self.net = GraphNetArrays(state, self.steps)
        self.prior_kind = self.config.get("prior", "none")
        self._stored = state if self.prior_kind == "linear" else None
        self._priors: dict = {}
        self.slot(part)

    @classmethod
    def from_checkpoint(cls, path, device: str = "cpu", **options):
        """The NumPy inference of the GNN checkpoint at ``path`` (``device`` must be ``cpu``)."""
        if device != "cpu":
            raise ValueError(f"the NumPy engine answers on the CPU, not on {device!r}")
        arrays, meta = checkpoint.read_arrays(path)
        if meta["kind"] != cls.name:
            raise ValueError(f"checkpoint {path} holds a {meta['kind']!r} model, not {cls.name!r}")
        state = {k[6:]: v for k, v in arrays.items() if k.startswith("model.")}
        p = cls(checkpoint_part(path, arrays, meta), meta["config"], state, **options)
        p.restore(path, meta)
        return p

    def n_parameters(self) -> int:
        return int(self.meta.get("parameters", 0))

    # -- the prior
    def restored(self) -> None:
        if self.prior_kind in HOLDING:
            self._held = HeldSkin(self.part, **self.meta["holding"]["skin"])
        if self.prior_kind != "linear":
            return
        op = self.meta.get("operator") or {}
        if op.get("mode") == "on_demand":
            self._priors[0] = ColumnPrior(self._store(self.part))
        else:
            s = self._stored
            self._priors[0] = StoredPrior(
                s["prior.levels"], s["prior.index"], s["prior.values"], self.part.n_vertices
            )
        self._stored = None

    def _store(self, part):
        op = self.meta.get("operator") or {}
        if op.get("mode") != "on_demand":
            raise ValueError(
                f"{self.name}: the linear FEM of another body needs the on-demand operator "
                "(operator: on_demand)"
            )
        return ColumnStore(part, op["setup"], [float(x) * 1e-3 for x in op["levels_mm"]])

    def _prior(self, k: int):
        if k not in self._priors:
            self._priors[k] = ColumnPrior(self._store(self.body_parts[k]), exact=True)
        return self._priors[k]

    def ahead(self, scenes) -> None:
        """The linear prior's columns a batch needs on each of its bodies, solved at once
        before the batch is answered chunk by chunk.
        """
        if self.prior_kind != "linear":
            return
        slots = np.asarray([self.slot(s.part) if self.general else 0 for s in scenes])
        for k in np.unique(slots):
            group = [s for s, j in zip(scenes, slots) if j == k]
            t = np.stack([s.thickness for s in group]).astype(np.float32)
            self._prior(int(k))(t, np.stack([s.force for s in group]).astype(np.float32))

    # -- inputs
    def body_tensors(self, part) -> dict:
        """Per body: vertex areas' inverse ``inv_area`` ``(N,)`` (1/m^2), ``normals``
        ``(N, 3)`` and the encoded edges ``(2E, latent)`` in :attr:`_ei`'s order, and target
        by target (``sorted_edges``, as the whole part's graph reads them).
        """
        rel = part.vertices[self._ei[0]] - part.vertices[self._ei[1]]  # x_j - x_i, m
        attr = np.concatenate([rel, np.linalg.norm(rel, axis=1, keepdims=True)], 1)
        edges = self.net.encode_edges(attr.astype(np.float32))
        return {
            "inv_area": (1.0 / part.vertex_areas).astype(np.float32),
            "normals": np.asarray(part.normals, np.float32),
            "edges": edges,
            "sorted_edges": np.ascontiguousarray(edges[self._order]),
        }

    def _answers(self, scenes) -> list:
        with blas().limit(limits=1, user_api="blas"):
            return self._answered(scenes)

    def _answered(self, scenes) -> list:
        """:meth:`_answers` on one BLAS thread."""
        B, N = len(scenes), self.part.n_vertices
        t = np.stack([s.thickness for s in scenes]).astype(np.float32)
        given = self.given(scenes).astype(np.float32)
        f = gap_of(given)
        slots = [self.slot(s.part) if self.general else 0 for s in scenes]
        inv_area = np.stack([self._body_data[k]["inv_area"] for k in slots])
        normals = np.stack([self._body_data[k]["normals"] for k in slots])
        total = f.sum(-1)
        if self.posed:  # how deep inside an object, how far outside; the way they move
            load = [np.maximum(-f, 0.0), np.clip(f, 0.0, GAP_REACH), *way_channels(given)]
        elif self.per_newton:
            pattern = f / np.maximum(total, MIN_TOTAL_N)[:, None]
            load = [pattern * inv_area, np.broadcast_to(total[:, None], f.shape)]
        else:
            load = [f * inv_area]
        base = None
        if self.prior_kind == "linear":  # the linear FEM's answer, in the units of the output
            base = np.zeros((B, N, 3), np.float32)
            for k in sorted(set(slots)):
                at = [b for b, s in enumerate(slots) if s == k]
                base[at] = self._prior(k)(t[at], f[at])
            base /= self.scale
            if self.per_newton:
                base /= np.maximum(total, MIN_TOTAL_N)[:, None, None]
        channels = [c[..., None] for c in load] + [t[..., None], normals]
        near = None
        if self.prior_kind == "closure":  # the linear FEM's closure of the objects, an input
            closing = self.closure_options()
            near = np.stack(
                [self._held.closure(f[b], given[b, :, 1:4], t[b], *closing) for b in range(B)]
            ) / np.float32(self.scale)
            channels.append(near)
        x = np.concatenate(channels + ([] if base is None else [base]), -1)
        out = self._network(x.reshape(B * N, -1), f, t, base, slots).reshape(B, N, -1)
        if self.posed:
            out = self._posed(out, near, normals, f, t)
        elif self.per_newton:
            out = out * total[:, None, None]
        u = list((out[..., :3] * self.scale).astype(np.float64))
        if not self.posed:
            return u
        pressures = out[..., 3:].astype(np.float64) * PRESSURE_OUT_SCALE
        squeeze = squeezes(self.config)
        return [
            posed_answer(s, x, p[:, 0], p[:, 1], squeeze) for s, x, p in zip(scenes, u, pressures)
        ]

    def _posed(self, out, near, normals, f, t) -> np.ndarray:
        """A pose model's network output ``(B, N, C)`` read: its pressures from their
        logarithm, its displacement on its prior (the skin inside an object moved out, or the
        linear FEM's closure ``near``), held near the objects and the linear FEM's beyond, or
        with ``held_answer: force`` moved on the held skin and pushed there. ``(B, N, 5)``.
        """
        forces = None
        if self.config.get("held_answer") == "force":
            out, forces = out[..., :5], out[..., 5:]
        out[..., 3:] = np.exp(np.minimum(out[..., 3:], PRESSURE_LOG_MAX))
        if self.prior_kind in ("contact", "held"):  # the skin inside an object moved out
            out[..., :3] += normals * np.minimum(f, 0.0)[..., None] / self.scale
        if forces is not None:  # the closure, moved on the held skin and pushed there
            for b in range(len(out)):
                out[b, :, :3] = near[b] + self._held.push(out[b, :, :3], forces[b], f[b], t[b])
            return out
        if near is not None:  # ... or the linear FEM's closure of the objects
            out[..., :3] += near
        if self.prior_kind in HOLDING:  # ... held near the objects, the linear FEM beyond
            for b in range(len(out)):
                out[b, :, :3] = self._held.answer(out[b, :, :3], f[b], t[b])
        return out

    @property
    def held_only(self) -> bool:
        """:func:`models.features.runs_held_only` of this network's options."""
        return runs_held_only(self.config)

    def _network(self, x, f, t, base, slots) -> np.ndarray:
        """The network's output ``(B N, C)`` with the prior (:meth:`_answers`), on the whole
        part or at fidelity ``auto`` on each scene's subgraph.
        """
        B, N = f.shape
        E = self._ei.shape[1]
        if self.fidelity != "auto" and not self.held_only:
            edges = [self._body_data[k]["sorted_edges"] for k in slots]
            edges = edges[0] if B == 1 else np.concatenate(edges)
            ei = (
                self._sorted
                if B == 1
                else np.tile(self._sorted, B) + np.repeat(np.arange(B) * N, E)
            )
            y = self.net(x, edges, ei)
            return y if base is None else base.reshape(B * N, 3) + CORRECTION_SCALE * y
        near = near_objects(f) if self.posed else f
        if self.held_only:  # the held vertices: the only answers the held prior reads
            seeds, grow = within_reach(f), 0
        elif base is not None:  # the region: where the linear FEM moves the tissue, a ring wider
            seeds, grow = reach.moving(near, base, self.region_tolerance), 1
        else:
            seeds, grow = reach.within_margin(self.part, t, near), 0
        g = subgraph(self._mesh, self.part, seeds, self.steps, grow, kernel=loaded())
        ei = g.edges
        if np.any(np.diff(ei[1]) < 0):  # the subgraph's edges come target by target
            raise RuntimeError("the subgraph's edges are not grouped by their target")
        scene, e = np.divmod(g.rows, E)
        edges = np.empty((len(e), self.net.steps[0]["A"].shape[0]), np.float32)
        for k in sorted(set(slots)):
            at = np.flatnonzero(np.asarray(slots)[scene] == k)
            edges[at] = self._body_data[k]["edges"][e[at]]
        y = self.net(x[g.nodes], edges, ei, sizes=g.sizes(self.steps))
        idx = g.nodes[: len(y)]
        if base is None:  # the network inside, zero outside
            out = np.zeros((B * N, y.shape[1]), np.float32)
            out[idx] = y
            return out
        out = base.reshape(B * N, 3).copy()  # the prior, corrected inside
        out[idx] += CORRECTION_SCALE * y
        return out
