"""A MeshGraphNets-style GNN on the body part's mesh, and its predictor.

Encode - process - decode (Pfaff et al. 2021), on the part's vertices and edges:

    h_i = f_v(node inputs_i),        e_ij = f_e(edge inputs_ij)                 (encoder)
    e_ij <- e_ij + g_e([e_ij, h_i, h_j]);  h_i <- h_i + g_v([h_i, sum_j e_ij])  (x steps)
    u_i = d(h_i)                                                                 (decoder)

Every MLP has two layers and (except the decoder) a LayerNorm. The network sees only graphs; the
predictor builds the features in SI units and :class:`Normaliser` modules (fixed shift and scale,
kept as buffers, so the checkpoint carries them) bring them to order one. Node inputs:
pressure ``F_i / A_i`` over 1 kPa, thickness normalised over [2.5, 12.5] mm, the outward normal.
Edge inputs: the rest-pose offset ``x_j - x_i`` over the mean edge length, and its length. Output:
the displacement over ``disp_scale_mm``. A seam vertex is one node, so there is no seam by
construction.
With ``prior: linear`` the precomputed linear FEM's displacement is three more node inputs and the
output is a correction to it (:class:`~models.linear.LinearPrior`).
"""

from __future__ import annotations

import warnings

import numpy as np
import torch
from torch import nn

with warnings.catch_warnings():  # torch_geometric's pooling layers use torch.jit.script on import
    warnings.filterwarnings(
        "ignore", message=r".*torch\.jit\.script.*deprecated", category=DeprecationWarning
    )
    from torch_geometric.nn import MessagePassing  # deferred: imports torch._dynamo (1-2 s)

from fem.local import first_margin
from models.features import (
    PRESSURE_SCALE,
    PRIOR_SCALE,
    THICKNESS_SCALE,
    THICKNESS_SHIFT,
    load_channels,
)
from models.learned import LearnedPredictor
from models.linear.operator import ComplianceOperator
from models.prior import LinearPrior, moved


def mlp(c_in: int, hidden: int, c_out: int, norm: bool = True) -> nn.Sequential:
    """Two linear layers with a ReLU between, optionally a LayerNorm on the output."""
    layers = [nn.Linear(c_in, hidden), nn.ReLU(), nn.Linear(hidden, c_out)]
    return nn.Sequential(*layers, nn.LayerNorm(c_out)) if norm else nn.Sequential(*layers)


class GraphNetBlock(MessagePassing):
    """One processor step: ``e_ij <- e_ij + g_e([e_ij, h_i, h_j])``, then
    ``h_i <- h_i + g_v([h_i, sum_j e_ij])``. ``h``: ``(V, L)``, ``e``: ``(E, L)``,
    ``edge_index``: ``(2, E)`` (source j, target i).

    ``g_e``'s first layer is applied as ``A e_ij + B h_i + C h_j``: the same map as on the
    concatenation, but ``B h`` and ``C h`` are computed once per node and gathered, which saves
    two thirds of the edge work (there are about six times more edges than nodes). Gathers use
    ``index_select``, six times faster than advanced indexing on the CPU at these sizes, and the
    sum over incoming edges is one ``index_add_`` (the same sum as ``propagate`` with
    ``aggr="add"``, without its per-call overhead: 10 % of a batch-1 prediction).
    """

    def __init__(self, latent: int):
        super().__init__(aggr="add")
        self.edge_in = nn.Linear(3 * latent, latent)
        self.edge_out = nn.Sequential(nn.ReLU(), nn.Linear(latent, latent), nn.LayerNorm(latent))
        self.node_mlp = mlp(2 * latent, latent, latent)

    def forward(
        self, h: torch.Tensor, edge_index: torch.Tensor, e: torch.Tensor, n: int | None = None
    ):
        """``n``: update only the first ``n`` nodes (every target of ``edge_index`` among
        them; sources may be any node of ``h``): ``(n, L)`` out instead of ``(V, L)``.
        """
        j, i = edge_index
        L = h.shape[1]
        if n is not None:
            h, h_all = h[:n], h
        else:
            h_all = h
        W, b = self.edge_in.weight, self.edge_in.bias
        hi, hj = h @ W[:, L : 2 * L].T, h_all @ W[:, 2 * L :].T  # per node, then gathered
        nodes = torch.index_select(hi, 0, i) + torch.index_select(hj, 0, j) + b
        e = e + self.edge_out(torch.addmm(nodes, e, W[:, :L].T))
        agg = torch.zeros_like(h).index_add_(0, i, e)  # sum_j e_ij at node i
        return h + self.node_mlp(torch.cat([h, agg], dim=-1)), e


class Normaliser(nn.Module):
    """Fixed feature normalisation ``(x - shift) / scale`` per channel, kept as buffers so that a
    checkpoint carries it. ``x``: ``(..., C)``.
    """

    def __init__(self, shift, scale):
        super().__init__()
        self.register_buffer("shift", torch.as_tensor(shift, dtype=torch.float32))
        self.register_buffer("scale", torch.as_tensor(scale, dtype=torch.float32))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return (x - self.shift) / self.scale


class NormalisedGraphNet(nn.Module):
    """A :class:`MeshGraphNet` behind its input normalisers: raw node and edge features in SI
    units in, the network's output out. ``prior``: an optional linear FEM operator
    (:class:`~models.linear.ComplianceOperator`) the predictor adds to the output, kept here so
    the checkpoint carries it.
    """

    def __init__(
        self,
        node_norm: Normaliser,
        edge_norm: Normaliser,
        net: "MeshGraphNet",
        prior: nn.Module | None = None,
    ):
        super().__init__()
        self.node_norm, self.edge_norm, self.net = node_norm, edge_norm, net
        if prior is not None:
            self.prior = prior

    def forward(self, x, edge_attr, edge_index, edges=None, sizes=None):
        """``edges``: the encoded ``edge_attr`` if known (:meth:`encode_edges`), else None;
        ``sizes``: see :meth:`MeshGraphNet.forward`.
        """
        if edges is None:
            edges = self.encode_edges(edge_attr)
        return self.net(self.node_norm(x), edges, edge_index, sizes)

    def encode_edges(self, edge_attr):
        """``(E, edge_in)`` raw edge features -> ``(E, latent)`` encoded."""
        return self.net.edge_encoder(self.edge_norm(edge_attr))


class MeshGraphNet(nn.Module):
    """``(V, node_in), (E, edge_in), (2, E) -> (V, out)``."""

    def __init__(
        self, node_in: int = 5, edge_in: int = 4, out: int = 3, latent: int = 128, steps: int = 15
    ):
        super().__init__()
        self.node_encoder = mlp(node_in, latent, latent)
        self.edge_encoder = mlp(edge_in, latent, latent)
        self.processor = nn.ModuleList(GraphNetBlock(latent) for _ in range(steps))
        self.decoder = mlp(latent, latent, out, norm=False)

    def forward(
        self,
        x: torch.Tensor,
        e: torch.Tensor,
        edge_index: torch.Tensor,
        sizes: list[tuple[int, int]] | None = None,
    ):
        """``x`` normalised node features, ``e`` encoded edges ``(E, latent)``.

        ``sizes``: one ``(n, m)`` per step for a graph whose nodes are sorted by their distance
        in hops from the nodes whose answer is wanted, and its edges by their target's: step
        ``s`` updates only the first ``n`` nodes over the first ``m`` edges (the nodes within
        ``steps - s`` hops, all that later steps read), and the output is the last step's
        ``(n, out)``; the same answer on those nodes as the whole graph's, with a third less work
        at three steps.
        """
        h = self.node_encoder(x)
        for s, block in enumerate(self.processor):
            if sizes is None:
                h, e = block(h, edge_index, e)
            else:
                n, m = sizes[s]
                h, e = block(h, edge_index[:, :m], e[:m], n)
        return self.decoder(h)


class GNNPredictor(LinearPrior, LearnedPredictor):
    """Mesh GNN predictor. Options: ``latent`` (width), ``steps`` (message passing),
    ``geometry`` (serve every body of the part's mesh: each scene's own rest-pose edge offsets,
    normals and vertex areas are the inputs, not those of the body it was built on),
    ``per_newton`` (node inputs: the pressure per newton of the total and the total; output:
    the displacement per newton, ``disp_scale_mm`` then in mm/N), ``loss`` (``mse``,
    ``relative`` or ``pooled``, see :meth:`LearnedPredictor.loss`), ``prior`` (``none``, or
    ``linear``: the precomputed linear FEM's displacement, :mod:`models.linear`, is a node input
    and the network predicts only the correction to it; :meth:`fit` computes the operator from
    the dataset).
    """

    name = "gnn"
    defaults = {
        "latent": 128,
        "steps": 15,
        "per_newton": False,
        "loss": "mse",
        "prior": "none",
        "operator": "stored",
        "geometry": False,
    }

    def edge_features(self, part) -> np.ndarray:
        """``(2E, 4)`` edge inputs of a body of the mesh: the rest-pose offset ``x_j - x_i``
        (m) along :attr:`edge_index` and its length.
        """
        ei = self._ei
        rel = part.vertices[ei[0]] - part.vertices[ei[1]]  # x_j - x_i, m
        return np.concatenate([rel, np.linalg.norm(rel, axis=1, keepdims=True)], 1)

    def body_tensors(self, part) -> dict:
        out = super().body_tensors(part)
        out["edge_attr"] = torch.tensor(
            self.edge_features(part), dtype=torch.float32, device=self.device
        )
        return out

    def build_model(self) -> nn.Module:
        part = self.part
        e = part.edges
        self._ei = ei = np.concatenate([e, e[:, ::-1]]).T  # (2, 2E): both directions
        feats = self.edge_features(part)
        length = float(feats[:, 3].mean())
        dev = self.device
        self.edge_index = torch.tensor(ei.copy(), dtype=torch.long, device=dev)
        self.edge_attr = torch.tensor(feats, dtype=torch.float32, device=dev)
        self.normals = torch.tensor(part.normals, dtype=torch.float32, device=dev)
        self.inv_area = torch.tensor(1.0 / part.vertex_areas, dtype=torch.float32, device=dev)
        # node features: pressure (Pa, or Pa per N), [total force N], thickness m, normal
        load = ([0.0, 0.0], [PRESSURE_SCALE, 1.0]) if self.per_newton else ([0.0], [PRESSURE_SCALE])
        node = Normaliser(
            load[0] + [THICKNESS_SHIFT, 0, 0, 0], load[1] + [THICKNESS_SCALE, 1, 1, 1]
        )
        edge = Normaliser([0.0] * 4, [length] * 4)
        prior = None
        if self.prior:  # the linear FEM's answer, in the units of raw(), is one more input
            prior = ComplianceOperator()
            node = Normaliser(list(node.shift) + [0.0] * 3, list(node.scale) + [PRIOR_SCALE] * 3)
        net = MeshGraphNet(
            len(node.shift), 4, 3, int(self.config["latent"]), int(self.config["steps"])
        )
        if prior is not None:  # start from the linear FEM's answer: a silent decoder
            nn.init.zeros_(net.decoder[-1].weight)
            nn.init.zeros_(net.decoder[-1].bias)
        return NormalisedGraphNet(node, edge, net, prior)

    def raw(self, thickness, force, body=None, base=None):
        B, N = thickness.shape
        if body is None:
            inv_area, normals = self.inv_area, self.normals.expand(B, -1, -1)
        else:
            inv_area, normals = (
                self.body_tensor("inv_area", body),
                self.body_tensor("normals", body),
            )
        load = torch.stack(load_channels(force, inv_area, self.per_newton), -1)
        base = self.base(thickness, force, body, base)
        extra = [] if base is None else [base]
        x = torch.cat([load, thickness[..., None], normals, *extra], -1)
        x = x.reshape(B * N, x.shape[-1])
        if self.fidelity == "auto" and not self.model.training:
            return self._raw_local(x, thickness, force, base, body)
        E = self.edge_index.shape[1]
        offs = (torch.arange(B, device=x.device) * N).repeat_interleave(E)
        ei = self.edge_index.repeat(1, B) + offs
        return self.corrected(
            base, self.model(x, None, ei, self.batch_edges(body, B)).reshape(B, N, 3)
        )

    def batch_edges(self, body, B: int) -> torch.Tensor:
        """``(B E, latent)``: each sample's body's encoded edges, sample after sample."""
        if body is None:
            return self.edges().repeat(B, 1)
        uniq, inv = torch.unique(body, return_inverse=True)
        enc = torch.stack([self.edges(int(k)) for k in uniq])  # (U, E, latent)
        return enc.index_select(0, inv).reshape(-1, enc.shape[-1])

    def edges(self, k: int = 0) -> torch.Tensor:
        """Body slot ``k``'s encoded edge features ``(E, latent)`` (0: the model's own part): a
        pure function of the mesh and the edge encoder's weights, so at inference they are kept
        until the weights change.
        """
        attr = self.edge_attr if k == 0 else self._body_data[k]["edge_attr"]
        if self.model.training or torch.is_grad_enabled():
            return self.model.encode_edges(attr)
        tensors = getattr(self, "_edge_tensors", (None, []))  # what the encoded edges depend on
        if tensors[0] is not self.model:
            self._edge_tensors = tensors = (
                self.model,
                [*self.model.net.edge_encoder.parameters(), *self.model.edge_norm.buffers()],
            )
        version = [id(self.model)] + [t._version for t in tensors[1]]
        cache = self.__dict__.setdefault("_edges", {})
        cached = cache.get(k)
        if cached is None or cached[0] != version:
            cache[k] = cached = (version, self.model.encode_edges(attr))
        return cached[1]

    def region(
        self, thickness: np.ndarray, force: np.ndarray, base: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """``fidelity="auto"``: per scene ``(B, N)`` masks of the vertices whose answer the
        network gives and of the subgraph it runs on (that region and ``steps`` hops more,
        every input its answer depends on). The region is where the load moves the tissue: with
        the linear prior ``base`` ``(B, N, 3)``, :func:`models.prior.moved` (the loaded vertices
        and those the prior moves by more than 1 % of its deepest, one ring wider); without
        it, within :func:`fem.local.first_margin` of the load, as hops along the mesh's edges.
        ``thickness``, ``force`` ``(B, N)`` numpy.
        """
        level = self.hops(thickness, force, base)
        return level == 0, level <= int(self.config["steps"])

    def hops(
        self, thickness: np.ndarray, force: np.ndarray, base: np.ndarray | None = None
    ) -> np.ndarray:
        """``(B, N)`` int: 0 on the vertices of :meth:`region`, ``k`` on those ``k`` hops from
        it (``k <= steps``: the subgraph), ``steps + 1`` beyond.
        """
        if getattr(self, "_adjacency", None) is None:
            e = self.part.edges
            self._adjacency = self.part.adjacency.astype(np.float32)
            self._edge = float(
                np.median(np.linalg.norm(np.diff(self.part.vertices[e], axis=1)[:, 0], axis=1))
            )
        steps = int(self.config["steps"])
        if base is not None:  # where the linear FEM moves the tissue
            inner = moved(self.part, force, base, rings=1)
        else:
            inner = np.zeros(force.shape, bool)
            for b in range(len(force)):
                m = force[b] > 0
                if not m.any():
                    continue
                hops = int(np.ceil(first_margin(self.part, thickness[b], force[b]) / self._edge))
                for _ in range(hops):
                    m = m | (self._adjacency @ m.astype(np.float32) > 0)
                inner[b] = m
        level = np.where(inner, 0, steps + 1)
        sub = inner
        for k in range(1, steps + 1):
            grown = sub | (self._adjacency @ sub.T.astype(np.float32) > 0).T
            level[grown & ~sub] = k
            sub = grown
        return level

    def _raw_local(self, x, thickness, force, base, body=None):
        """:meth:`raw` on the subgraphs of :meth:`region`: the network's output inside each
        scene's region, the prior (or zero) outside. The subgraph's nodes are sorted by their
        hops from the region (:meth:`hops`) and its edges by their target's, so that each step
        updates only the nodes later steps read (:meth:`MeshGraphNet.forward`'s ``sizes``).
        """
        B, N = thickness.shape
        steps = int(self.config["steps"])
        level = self.hops(
            thickness.cpu().numpy(),
            force.cpu().numpy(),
            None if base is None else base.detach().cpu().numpy(),
        ).ravel()
        sub = np.flatnonzero(level <= steps)  # global ids b * N + i
        nodes = sub[np.argsort(level[sub], kind="stable")]
        where = np.full(B * N, -1)
        where[nodes] = np.arange(len(nodes))
        ei = self.edge_index.cpu().numpy()
        src = (ei[0][None] + N * np.arange(B)[:, None]).ravel()
        dst = (ei[1][None] + N * np.arange(B)[:, None]).ravel()
        keep = np.flatnonzero((where[src] >= 0) & (level[dst] < steps))  # edges a step reads
        keep = keep[np.argsort(level[dst[keep]], kind="stable")]
        counts = np.bincount(level[nodes], minlength=steps + 1)
        edge_counts = np.bincount(level[dst[keep]], minlength=steps + 1)
        sizes = [
            (int(counts[: steps - s + 1].sum()), int(edge_counts[: steps - s + 1].sum()))
            for s in range(1, steps + 1)
        ]
        dev = x.device
        sub_ei = torch.as_tensor(np.stack([where[src[keep]], where[dst[keep]]]), device=dev)
        E = ei.shape[1]
        if body is None:
            sub_e = self.edges().index_select(0, torch.as_tensor(keep % E, device=dev))
        else:
            sub_e = self.batch_edges(body, B).index_select(0, torch.as_tensor(keep, device=dev))
        idx = torch.as_tensor(nodes, device=dev)
        y = self.model(x.index_select(0, idx), None, sub_ei, sub_e, sizes=sizes)  # (inner, 3)
        out = torch.zeros(B * N, 3, device=dev, dtype=y.dtype)
        out[idx[: len(y)]] = y
        return self.corrected(base, out.reshape(B, N, 3))
