"""The graph network's processor for inference on the CPU with its elementwise work fused: the
same steps as :class:`~models.gnn.network.GraphNetBlock`, the matrix products left to torch and
everything between them done in three compiled loops (Numba) over rows, in place.

Per step, with ``g_e``'s first layer split as ``A e_ij + B h_i + C h_j``:

    z_ij = relu(A e_ij + b + (B h)_i + (C h)_j)        products; one loop: gather, relu
    e_ij <- e_ij + LN(W z_ij + c);  a_i = sum_j e_ij   a product; one loop: norm, residual, sum
    h_i <- h_i + LN(V2 relu(V1 [h_i, a_i] + d) + d2)   products; one loop: norm, residual

Eager torch runs each of these as its own operation over the whole edge or node array, with a
temporary for each (gathers, sums, norms): about sixteen passes over memory a step, each a
call of some tens of microseconds. Here the loops read each row once. The answers equal the
eager network's within float32 rounding (the norms sum in another order: some 1e-7 of the
largest output).

Used only for inference (no gradients, module in eval mode, CPU tensors) and only once Numba
is loaded (:func:`kernels`): importing it costs a process about half a second, which a one-off
answer does not pay back. :meth:`models.gnn.predictor.GNNPredictor.load_kernels` loads it.
"""

from __future__ import annotations

import functools
import sys

import numpy as np
import torch
from torch import nn


def _edge_in(z, bc, i, j):
    """``z[k] <- relu(z[k] + bc[i[k], :L] + bc[j[k], L:])`` in place; ``z`` ``(m, L)``,
    ``bc`` ``(V, 2L)``.
    """
    L = z.shape[1]
    for k in range(z.shape[0]):
        a = i[k]
        b = j[k]
        for c in range(L):
            v = z[k, c] + bc[a, c] + bc[b, L + c]
            z[k, c] = v if v > 0.0 else 0.0


def _edge_out(y, e, gamma, beta, eps, i, agg):
    """``y[k] <- e[k] + LN(y[k])`` in place and ``agg[i[k]] += y[k]`` (``agg`` zeroed first);
    ``y``, ``e`` ``(m, L)``, ``agg`` ``(n, L)``.
    """
    L = y.shape[1]
    agg[:] = 0.0
    for k in range(y.shape[0]):
        s = 0.0
        for c in range(L):
            s += y[k, c]
        mean = s / L
        s = 0.0
        for c in range(L):
            d = y[k, c] - mean
            s += d * d
        inv = 1.0 / np.sqrt(s / L + eps)
        t = i[k]
        for c in range(L):
            v = e[k, c] + (y[k, c] - mean) * inv * gamma[c] + beta[c]
            y[k, c] = v
            agg[t, c] += v


def _node_out(y, h, gamma, beta, eps):
    """``y[k] <- h[k] + LN(y[k])`` in place; ``y`` ``(n, L)``, ``h`` ``(>= n, L)``. (The
    :func:`_edge_out` loop without its sum: one loop with a flag for the sum ran 2.7 times
    slower, its inner loop no longer vectorised.)
    """
    L = y.shape[1]
    for k in range(y.shape[0]):
        s = 0.0
        for c in range(L):
            s += y[k, c]
        mean = s / L
        s = 0.0
        for c in range(L):
            d = y[k, c] - mean
            s += d * d
        inv = 1.0 / np.sqrt(s / L + eps)
        for c in range(L):
            y[k, c] = h[k, c] + (y[k, c] - mean) * inv * gamma[c] + beta[c]


@functools.cache
def _compiled():
    """The three loops compiled (Numba's disk cache: some tenths of a second in a new process),
    or None without Numba.
    """
    try:
        from numba import njit  # deferred: about half a second to import
    except ImportError:
        return None
    jit = njit(cache=True, nogil=True, fastmath=True)
    return jit(_edge_in), jit(_edge_out), jit(_node_out)


def kernels(load: bool = False):
    """The compiled loops, or None: without Numba, or when it is not yet imported in this
    process and ``load`` is False.
    """
    if not load and "numba" not in sys.modules:
        return None
    return _compiled()


def usable(h: torch.Tensor) -> bool:
    """Whether an answer on node states ``h`` may take the fused path: inference on the CPU in
    float32, outside ``torch.compile``'s tracing, with the loops loaded.
    """
    return (
        not torch.is_grad_enabled()
        and h.device.type == "cpu"
        and h.dtype == torch.float32
        and not torch.compiler.is_compiling()
        and kernels() is not None
    )


class _Step:
    """One :class:`GraphNetBlock`'s weights laid out for :func:`processor` (the products' right
    factors transposed once; the norms' parameters as arrays).
    """

    def __init__(self, block: nn.Module):
        L = block.edge_in.weight.shape[0]
        W = block.edge_in.weight.detach()
        first, _, second, norm = block.node_mlp
        V = first.weight.detach()
        t = lambda x: x.detach().T.contiguous()  # noqa: E731
        a = lambda x: x.detach().numpy()  # noqa: E731
        self.BC = torch.cat([W[:, L : 2 * L], W[:, 2 * L :]]).T.contiguous()  # (L, 2L)
        self.A, self.a = W[:, :L].T.contiguous(), block.edge_in.bias.detach()
        self.W, self.w = t(block.edge_out[1].weight), block.edge_out[1].bias.detach()
        self.edge_norm = a(block.edge_out[2].weight), a(block.edge_out[2].bias)
        self.edge_eps = float(block.edge_out[2].eps)
        self.Vh, self.Va = V[:, :L].T.contiguous(), V[:, L:].T.contiguous()
        self.v = first.bias.detach()
        self.V2, self.v2 = t(second.weight), second.bias.detach()
        self.node_norm = a(norm.weight), a(norm.bias)
        self.node_eps = float(norm.eps)


def _steps(processor: nn.ModuleList) -> list[_Step]:
    """The processor's weights laid out once, again whenever a parameter's storage is replaced
    or changed in place (a loaded state, a training step: torch counts each tensor's versions).
    """
    cached = processor.__dict__.get("_fused")
    if cached is None:
        params = list(processor.parameters())  # walking the modules costs ~0.5 ms: once
    else:
        params = cached[0]
    key = [(p.data_ptr(), p._version) for p in params]
    if cached is None or cached[1] != key:
        cached = (params, key, [_Step(b) for b in processor])
        processor.__dict__["_fused"] = cached
    return cached[2]


def processor(
    processor: nn.ModuleList,
    h: torch.Tensor,
    e: torch.Tensor,
    edge_index: torch.Tensor,
    sizes: list[tuple[int, int]] | None = None,
) -> torch.Tensor:
    """:class:`MeshGraphNet`'s processor steps on ``h`` ``(V, L)``, encoded edges ``e``
    ``(E, L)`` and ``edge_index`` ``(2, E)`` (source, target), ``sizes`` as its ``forward``
    takes them: the node states after the last step (``(n, L)`` of its last size, or
    ``(V, L)``). ``e`` is not changed.
    """
    edge_in, edge_out, node_out = kernels()
    j_all = edge_index[0].numpy()
    i_all = edge_index[1].numpy()
    h, e = h.detach().contiguous(), e.detach().contiguous()
    for s, w in enumerate(_steps(processor)):
        n, m = sizes[s] if sizes is not None else (h.shape[0], e.shape[0])
        i, j = i_all[:m], j_all[:m]
        bc = torch.mm(h, w.BC)
        z = torch.addmm(w.a, e[:m], w.A)
        edge_in(z.numpy(), bc.numpy(), i, j)
        y = torch.addmm(w.w, z, w.W)
        agg = torch.empty(n, h.shape[1])
        edge_out(y.numpy(), e[:m].numpy(), *w.edge_norm, w.edge_eps, i, agg.numpy())
        hn = h[:n]
        z = torch.addmm(w.v, hn, w.Vh).addmm_(agg, w.Va).relu_()
        out = torch.addmm(w.v2, z, w.V2)
        node_out(out.numpy(), hn.numpy(), *w.node_norm, w.node_eps)
        h, e = out, y
    return h
