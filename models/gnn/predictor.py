"""The mesh GNN predictor: the graph network of :mod:`models.gnn.network` on the body part's mesh.

Node inputs: pressure ``F_i / A_i`` over 1 kPa, thickness normalised over [2.5, 12.5] mm, the
outward normal. Edge inputs: the rest-pose offset ``x_j - x_i`` over the mean edge length, and
its length. Output: the displacement over ``disp_scale_mm``. A seam vertex is one node, so there
is no seam by construction. With ``prior: linear`` the precomputed linear FEM's displacement is
three more node inputs and the output is a correction to it
(:class:`~models.prior.LinearPrior`). With ``given: pose`` the load's inputs are an object's
pose instead (how deep each vertex lies inside it, over 10 mm, and how far outside, over 20 mm:
:func:`~models.features.gap_channels`) and two more outputs are the contact pressure and its
push along the press (the reaction's density).
"""

from __future__ import annotations

import numpy as np
import torch
from torch import nn

from models.features import (
    GAP_SCALE,
    PRESSURE_SCALE,
    PRIOR_SCALE,
    THICKNESS_SCALE,
    THICKNESS_SHIFT,
    gap_channels,
    gap_of,
    load_channels,
    near_objects,
    runs_held_only,
    way_channels,
)
from models.gnn import fused
from models.gnn.network import MeshGraphNet, NormalisedGraphNet, Normaliser
from models.gnn.subgraph import compiled, mesh, subgraph
from models.learned import LearnedPredictor
from models.linear.operator import ComplianceOperator
from models.prior import CORRECTION_SCALE, LinearPrior, start_silent
from stmpl import reach
from stmpl.pose import GAP_REACH, within_reach


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
    counts = ("latent", "steps")
    poses = True

    def network(self):
        """The graph network itself (:class:`MeshGraphNet`): normalisers and prior stay eager."""
        return self.model.net

    def load_kernels(self) -> None:
        """The subgraphs at fidelity ``auto`` from the compiled kernel
        (:func:`models.gnn.subgraph.compiled`) and the processor's steps fused
        (:mod:`models.gnn.fused`), from then on; and the linear prior's solves
        (:meth:`models.prior.LinearPrior.load_kernels`).
        """
        compiled()
        fused.kernels(load=True)
        super().load_kernels()

    def compile(self, scene=None) -> float:
        """As :meth:`LearnedPredictor.compile`, with :meth:`load_kernels` first."""
        self.load_kernels()
        return super().compile(scene)

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
        self._mesh = mesh(part, ei)  # what the subgraphs at fidelity auto read
        feats = self.edge_features(part)
        length = float(feats[:, 3].mean())
        dev = self.device
        self.edge_index = torch.tensor(ei.copy(), dtype=torch.long, device=dev)
        self.edge_attr = torch.tensor(feats, dtype=torch.float32, device=dev)
        self.normals = torch.tensor(part.normals, dtype=torch.float32, device=dev)
        self.inv_area = torch.tensor(1.0 / part.vertex_areas, dtype=torch.float32, device=dev)
        # node features: pressure (Pa, or Pa per N), [total force N], thickness m, normal
        load = ([0.0, 0.0], [PRESSURE_SCALE, 1.0]) if self.per_newton else ([0.0], [PRESSURE_SCALE])
        if self.posed:  # how deep inside an object, how far outside (m); the way they move
            load = ([0.0, 0.0], [GAP_SCALE, GAP_REACH])
            if self.motion:
                load = (load[0] + [0.0] * 3, load[1] + [1.0] * 3)
        node = Normaliser(
            load[0] + [THICKNESS_SHIFT, 0, 0, 0], load[1] + [THICKNESS_SCALE, 1, 1, 1]
        )
        edge = Normaliser([0.0] * 4, [length] * 4)
        prior = None
        if self.prior:  # the linear FEM's answer, in the units of raw(), is one more input
            prior = ComplianceOperator()
            node = Normaliser(list(node.shift) + [0.0] * 3, list(node.scale) + [PRIOR_SCALE] * 3)
        if self.config["prior"] == "closure":  # so is the linear FEM's closure of the objects
            node = Normaliser(list(node.shift) + [0.0] * 3, list(node.scale) + [PRIOR_SCALE] * 3)
        net = MeshGraphNet(
            len(node.shift),
            4,
            self.out_channels,
            int(self.config["latent"]),
            int(self.config["steps"]),
        )
        if prior is not None or self.posed:  # start from the prior (or the rest skin)
            start_silent(net.decoder[-1], self.posed)
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
        if self.posed:
            load = torch.stack(gap_channels(gap_of(force)) + way_channels(force), -1)
        else:
            load = torch.stack(load_channels(force, inv_area, self.per_newton), -1)
        base = self.base(thickness, force, body, base)
        extra = [] if base is None else [base]
        if self.config["prior"] == "closure":
            extra.append(self.closure_base(force, thickness, body))
        x = torch.cat([load, thickness[..., None], normals, *extra], -1)
        x = x.reshape(B * N, x.shape[-1])
        if self.local:
            return self._raw_local(x, thickness, force, base, body)
        E = self.edge_index.shape[1]
        offs = (torch.arange(B, device=x.device) * N).repeat_interleave(E)
        ei = self.edge_index.repeat(1, B) + offs
        return self.corrected(
            base, self.model(x, None, ei, self.batch_edges(body, B)).reshape(B, N, -1)
        )

    @property
    def held_only(self) -> bool:
        """:func:`models.features.runs_held_only` of this network's options."""
        return runs_held_only(self.config)

    @property
    def local(self) -> bool:
        """Whether the network runs on a subgraph (:meth:`_raw_local`): at fidelity ``auto``
        and with a held prior (:attr:`held_only`) in answers, and with a held prior in training
        where the loss reads the held vertices alone (not ``mse``, which reads every vertex's
        pressures).
        """
        if self.model.training:
            return self.held_only and self.config.get("loss", "mse") != "mse"
        return self.held_only or self.fidelity == "auto"

    def batch_edges(self, body, B: int, keep=None) -> torch.Tensor:
        """``(B E, latent)``: each sample's body's encoded edges, sample after sample; or only
        rows ``keep`` (ids ``b E + e``, numpy) of them.
        """
        E = self.edge_index.shape[1]
        slots = np.zeros(1, int) if body is None else body.cpu().numpy()
        if keep is None and B == 1:  # one scene's every edge: its body's encoded edges as kept
            return self.edges(int(slots[0]))
        rows = np.arange(B * E) if keep is None else np.asarray(keep)
        if (slots == slots[0]).all():  # one body: its own encoded edges, nothing copied
            enc, at = self.edges(int(slots[0])), rows % E
        else:  # the bodies' encoded edges one after another; each row's body's
            uniq, inv = np.unique(slots, return_inverse=True)
            enc = torch.cat([self.edges(int(k)) for k in uniq])  # (U E, latent)
            at = inv.ravel()[rows // E] * E + rows % E
        return enc.index_select(0, torch.as_tensor(at, device=enc.device))

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
        the linear prior ``base`` ``(B, N, 3)``, :func:`stmpl.reach.moved` (the loaded vertices
        and those the prior moves by more than 1 % of its deepest, one ring wider); without
        it, within :func:`stmpl.reach.first_margin` of the load, as hops along the mesh's edges.
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
        if base is not None:  # where the linear FEM moves the tissue
            inner = reach.moved(self.part, force, base, rings=1, tolerance=self.region_tolerance)
        else:
            inner = reach.within_margin(self.part, thickness, force)
        return reach.hops(self.part, inner, int(self.config["steps"]))

    def _raw_local(self, x, thickness, force, base, body=None):
        """:meth:`raw` on the subgraphs of :meth:`region`: the network's output inside each
        scene's region, the prior (or zero) outside. The subgraph (:mod:`models.gnn.subgraph`)
        has its nodes sorted by their hops from the region (as :meth:`hops` counts them) and its
        edges by their target's, so that each step updates only the nodes later steps read
        (:meth:`MeshGraphNet.forward`'s ``sizes``).
        """
        B, N = thickness.shape
        steps = int(self.config["steps"])
        f = (near_objects(gap_of(force)) if self.posed else force).cpu().numpy()
        if self.held_only:  # the held vertices: the only answers the held prior reads
            seeds, grow = within_reach(gap_of(force).cpu().numpy()), 0
        elif base is not None:  # the region: where the linear FEM moves the tissue, a ring wider
            seeds, grow = reach.moving(f, base.detach().cpu().numpy(), self.region_tolerance), 1
        else:
            seeds, grow = reach.within_margin(self.part, thickness.cpu().numpy(), f), 0
        g = subgraph(self._mesh, self.part, seeds, steps, grow)
        dev = x.device
        sub_ei = torch.as_tensor(g.edges, device=dev)
        sub_e = self.batch_edges(body, B, g.rows)
        idx = torch.as_tensor(g.nodes, device=dev)
        y = self.model(x.index_select(0, idx), None, sub_ei, sub_e, sizes=g.sizes(steps))
        if base is None:  # the network inside, zero outside
            out = y.new_zeros(B * N, y.shape[-1]).index_copy_(0, idx[: len(y)], y)
            return out.reshape(B, N, -1)
        out = base.reshape(B * N, 3).clone()  # the prior, corrected inside
        return out.index_add_(0, idx[: len(y)], y, alpha=CORRECTION_SCALE).reshape(B, N, 3)
