"""A MeshGraphNets-style graph network (Pfaff et al. 2021): graphs in, graphs out; it knows no
physics, scenes or envelopes (the predictor, :mod:`models.gnn.predictor`, builds its inputs).

Encode - process - decode, on a graph's nodes and edges:

    h_i = f_v(node inputs_i),        e_ij = f_e(edge inputs_ij)                 (encoder)
    e_ij <- e_ij + g_e([e_ij, h_i, h_j]);  h_i <- h_i + g_v([h_i, sum_j e_ij])  (x steps)
    u_i = d(h_i)                                                                 (decoder)

Every MLP has two layers and (except the decoder) a LayerNorm. :class:`Normaliser` modules (a
fixed shift and scale, kept as buffers, so a checkpoint carries them) bring the inputs to order
one; :class:`NormalisedGraphNet` applies them and, given one, adds a prior module's output to
the node inputs.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

from models.gnn import fused


def mlp(c_in: int, hidden: int, c_out: int, norm: bool = True) -> nn.Sequential:
    """Two linear layers with a ReLU between, optionally a LayerNorm on the output."""
    layers = [nn.Linear(c_in, hidden), nn.ReLU(), nn.Linear(hidden, c_out)]
    return nn.Sequential(*layers, nn.LayerNorm(c_out)) if norm else nn.Sequential(*layers)


class GraphNetBlock(nn.Module):
    """One processor step: ``e_ij <- e_ij + g_e([e_ij, h_i, h_j])``, then
    ``h_i <- h_i + g_v([h_i, sum_j e_ij])``. ``h``: ``(V, L)``, ``e``: ``(E, L)``,
    ``edge_index``: ``(2, E)`` (source j, target i).

    ``g_e``'s first layer is applied as ``A e_ij + B h_i + C h_j``: the same map as on the
    concatenation, but ``B h`` and ``C h`` are computed once per node and gathered, which saves
    two thirds of the edge work (there are about six times more edges than nodes). Gathers use
    ``index_select``, six times faster than advanced indexing on the CPU at these sizes, and the
    sum over incoming edges is one ``index_add_`` (plain torch: no graph library to import, and
    none of a message-passing framework's per-call overhead).
    """

    def __init__(self, latent: int):
        super().__init__()
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
        hn = h if n is None else h[:n]
        W = self.edge_in.weight  # (L, 3L): [A | B | C]
        bc = F.linear(h, torch.cat([W[:, L : 2 * L], W[:, 2 * L :]]))  # (V, 2L): B h, C h
        z = torch.addmm(self.edge_in.bias, e, W[:, :L].T)
        z = z.add_(bc[:, :L].index_select(0, i)).add_(bc[:, L:].index_select(0, j)).relu_()
        e = e + _normed(z, self.edge_out[1], self.edge_out[2])
        agg = hn.new_zeros(hn.shape).index_add_(0, i, e)  # sum_j e_ij at node i
        first, _, second, norm = self.node_mlp
        V = first.weight  # the node MLP's first layer on [h_i, agg_i], as two products
        y = torch.addmm(first.bias, hn, V[:, :L].T).addmm_(agg, V[:, L:].T).relu_()
        return hn + _normed(y, second, norm), e


def _normed(x: torch.Tensor, linear: nn.Linear, norm: nn.LayerNorm) -> torch.Tensor:
    """``norm(linear(x))`` without the modules' call overhead (a few microseconds each)."""
    y = torch.addmm(linear.bias, x, linear.weight.T)
    return F.layer_norm(y, norm.normalized_shape, norm.weight, norm.bias, norm.eps)


def _mlp(x: torch.Tensor, layers: nn.Sequential) -> torch.Tensor:
    """:func:`mlp`'s ``layers`` applied to ``x`` without the modules' call overhead."""
    first, _, second, *norm = layers
    y = torch.addmm(first.bias, x, first.weight.T).relu_()
    return _normed(y, second, norm[0]) if norm else torch.addmm(second.bias, y, second.weight.T)


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
        h = _mlp(x, self.node_encoder)
        # inference with the compiled loops (once loaded): the same steps, fewer passes
        if not self.training and fused.usable(h):
            return _mlp(fused.processor(self.processor, h, e, edge_index, sizes), self.decoder)
        for s, block in enumerate(self.processor):
            if sizes is None:
                h, e = block.forward(h, edge_index, e)
            else:
                n, m = sizes[s]
                h, e = block.forward(h, edge_index[:, :m], e[:m], n)
        return _mlp(h, self.decoder)
