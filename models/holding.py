"""The held prior (option ``prior: held``, a model given a pose): the network answers the skin
near the objects, and the tissue's linear FEM carries that answer to the rest of the skin.

Under a grip the fingers drag the skin along with them, and the stiff skin over soft fat carries
that drag along the whole limb: on the layered forearm most of a grip's displacement lies
centimetres from any contact, beyond a message-passing network's reach, where the strains are
small and the tissue linear. Held at the FEM's own displacement near the objects, the linear
FEM answers the rest of the skin within 0.14-0.55 % of the peak on average
(``benchmarks/grip_far_field.py``). So with this prior a model's displacement is

    u = G[:, H] G[H, H]^-1 r_H

with ``r`` the network's answer plus the contact prior (the skin inside an object moved out to
its surface, :meth:`~models.learned.LearnedPredictor.contact_base`), ``H`` the free skin
vertices within :data:`~stmpl.pose.GAP_REACH` of an object, and ``G`` the skin's 3D nodal
compliance at the sample's thickness (:class:`fem.holding.SkinCompliance`, solved once per
thickness and cached on disk). On ``H`` the answer is the network's own; elsewhere it is the
linear FEM's, and the loss over every vertex teaches the network a near field that the linear
FEM carries right. Torch, differentiable in ``r``.
"""

from __future__ import annotations

import time

import numpy as np
import torch

from fem import holding as fem_holding
from fem.closure import CONTACT_RULE
from fem.shapes import ROUNDING
from stmpl.contact.gap import of_sample
from stmpl.part import BodyPart
from stmpl.pose import GAP_REACH


class HeldSkin(fem_holding.HeldSkin):
    """:class:`fem.holding.HeldSkin` answered in torch (:meth:`__call__`), differentiable in
    the near answer.
    """

    def __init__(self, part: BodyPart, tissue: str, phenotype: dict | None = None):
        super().__init__(part, tissue, phenotype)
        self._tensors: dict = {}

    def __call__(self, r, gap, thickness):
        """``(B, N, 3)`` the skin held at ``r`` ``(B, N, 3)`` (any unit) on each sample's held
        vertices (``gap`` ``(B, N)``, m; ``thickness`` ``(B, N)``, m; torch), the linear FEM's
        answer elsewhere; zero where no object is near.
        """
        g = gap.detach().cpu().numpy()
        t = thickness.detach().cpu().numpy()
        out = []
        for b in range(len(r)):
            s, at, L = self.hold(g[b], t[b])
            if len(at) == 0:
                out.append(torch.zeros_like(r[b]))
                continue
            if id(L) not in self._tensors:  # the factor's and the store's tensors, kept
                if len(self._tensors) >= fem_holding.CACHED_HOLDS:
                    self._tensors.pop(next(iter(self._tensors)))
                self._tensors[id(L)] = (L, torch.from_numpy(at), torch.from_numpy(L))
            _, at_t, L_t = self._tensors[id(L)]
            dev = r.device
            rh = r[b].reshape(-1)[at_t.to(dev)].to(L_t.dtype)[:, None]
            f = torch.cholesky_solve(rh, L_t.to(dev)).to(r.dtype)[:, 0]
            if dev.type == "cpu" and not torch.is_grad_enabled():  # an answer: G read in place
                u = s.product(at, f.numpy())
                out.append(torch.from_numpy(u).to(r.dtype).reshape(r[b].shape))
                continue
            # G's transpose shares the store's memory on the CPU, row by row: a held
            # vertex's columns of G are its contiguous rows
            GT = torch.from_numpy(s.G.T).to(dev)
            out.append((f @ GT.index_select(0, at_t.to(dev))).reshape(r[b].shape))
        return torch.stack(out)

    def pushed(self, r, forces, gap, thickness):
        """:meth:`fem.holding.HeldSkin.push` of each sample in torch, differentiable in ``r``
        and ``forces`` ``(B, N, 3)``: the skin moved by ``r`` on the held vertices (of ``gap``
        and ``thickness`` ``(B, N)``, m) and everywhere by the forces on the held DOFs,
        carried by the compliance.
        """
        g = gap.detach().cpu().numpy()
        t = thickness.detach().cpu().numpy()
        out = []
        for b in range(len(r)):
            s, at, d = self.pushing(g[b], t[b])
            if len(at) == 0:
                out.append(torch.zeros_like(r[b]))
                continue
            dev = r.device
            at_t = torch.from_numpy(at).to(dev)
            scale = torch.from_numpy(d * fem_holding.PUSH_SPREAD).to(dev, r.dtype)
            f = forces[b].reshape(-1)[at_t] / scale
            if dev.type == "cpu" and not torch.is_grad_enabled():  # an answer: G read in place
                u = torch.from_numpy(s.product(at, f.numpy(), bits=16)).to(r.dtype)
            else:
                GT = torch.from_numpy(s.G.T).to(dev)  # a held DOF's column: a contiguous row
                u = (f.to(GT.dtype) @ GT.index_select(0, at_t)).to(r.dtype)
            moved = torch.zeros_like(u).index_add(0, at_t, r[b].reshape(-1)[at_t])
            out.append((u + moved).reshape(r[b].shape))
        return torch.stack(out)

    def forget_poses(self) -> None:
        super().forget_poses()
        self._tensors.clear()


def rounding_of(kinds) -> float | None:
    """m: how far outside the objects' faces the FEM's surface stood in a set of samples of
    ``kinds``: a grip's hand is a mesh, rounded by :data:`fem.shapes.ROUNDING`; a dataset's
    pressed ball and disk are analytic shapes, not rounded (what the closure prior replays).
    None for a set of both.
    """
    grips = {str(k) == "press_grip" for k in kinds}
    if len(grips) > 1:
        return None
    return ROUNDING if grips == {True} else 0.0


def fit_held(predictor, dataset, progress: bool = True) -> None:
    """Give ``predictor`` (option ``prior: held`` or ``closure``, or the linear FEM given a pose)
    its :class:`HeldSkin` for
    ``dataset``'s part and tissue, with the columns every sample of the set holds solved (cached
    on disk), and record it in ``predictor.meta["holding"]`` with the set's friction coefficient
    (the closure's).
    """
    cfg = dataset.card["config"]
    prior = predictor.config.get("prior")
    what = f"prior: {prior}" if prior else f"the {predictor.name} model given a pose"
    tissue = cfg.get("tissue") or "paper"
    if tissue == "paper":
        raise ValueError(
            f"{what} carries the skin by a layered tissue's linear FEM; this dataset's is the "
            "paper's gel" + (" (take prior: contact)" if prior else "")
        )
    body = cfg.get("body") or {}
    skin = {"tissue": tissue, "phenotype": cfg.get("phenotype", body.get("phenotype"))}
    h = HeldSkin(predictor.part, **skin)
    a = dataset.arrays()
    own = a.get("body", np.zeros(len(a["thickness"]), int)) == 0
    if not own.all():
        raise ValueError(f"{what} knows the linear FEM of the model's own body only")
    rounding = rounding_of(a["kind"])
    if rounding is None and prior in ("closure", None):
        raise ValueError(
            f"this set mixes grips (a rounded mesh) with analytic presses (not rounded): {what} "
            "replays one or the other"
        )
    t0 = time.perf_counter()
    gaps = [
        of_sample(predictor.part.vertices, k, params, g)
        for k, params, g in zip(a["kind"], a["params"], a["gap"])
    ]
    solved = h.prepare(gaps, a["thickness"], progress)
    predictor.held_skin = h
    predictor.meta["holding"] = {
        "skin": skin,
        "friction": float(cfg.get("friction") or 0.0),
        "rounding_m": rounding,
        "contact_rule": CONTACT_RULE,
        "reach_m": GAP_REACH,
        "columns_at_fit": int(solved),
        "compute_seconds": round(time.perf_counter() - t0, 3),
    }
