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

from fem.holding import SkinCompliance
from stmpl.contact.gap import of_sample
from stmpl.part import BodyPart
from stmpl.pose import GAP_REACH

REACH_TOLERANCE = 1e-6
"""m: a vertex is within reach of an object where its gap is below :data:`GAP_REACH` by more
than this (the gap is cut at ``GAP_REACH``, and a float32 copy of the cut value lies just below
it)."""

CACHED_HOLDS = 256
"""Factorised holds (one per distinct held set and thickness) kept in memory; a training set's
samples each have one (some 20-50 MB a sample on the forearm)."""


def within_reach(gap) -> np.ndarray:
    """``(..., N)`` bool: the vertices an object lies within :data:`GAP_REACH` of, from their
    gap ``(..., N)`` (m, NumPy): those the held prior holds.
    """
    return np.asarray(gap, dtype=float) < GAP_REACH - REACH_TOLERANCE


class HeldSkin:
    """The held prior of one body ``part`` and ``tissue`` (a layered preset's name, with the
    body's ``phenotype``): :meth:`__call__` carries a near answer to the whole skin.
    """

    def __init__(self, part: BodyPart, tissue: str, phenotype: dict | None = None):
        self.part, self.tissue, self.phenotype = part, tissue, phenotype
        self._stores: dict[bytes, SkinCompliance] = {}
        self._G: dict[bytes, torch.Tensor] = {}
        self._holds: dict[tuple, tuple] = {}

    def record(self) -> dict:
        """What a checkpoint keeps to make the prior again."""
        return {"tissue": self.tissue, "phenotype": self.phenotype, "reach_m": GAP_REACH}

    def store(self, thickness) -> tuple[bytes, SkinCompliance]:
        """The compliance of the skin at ``thickness`` ``(N,)`` (m), and its key."""
        t = np.asarray(thickness, dtype=np.float32)
        key = t.tobytes()
        if key not in self._stores:
            self._stores[key] = SkinCompliance(self.part, t, self.tissue, self.phenotype)
        return key, self._stores[key]

    def held(self, gap, thickness) -> np.ndarray:
        """``(k,)`` the vertices a sample with ``gap`` ``(N,)`` (m) and ``thickness`` holds:
        the free ones within :data:`GAP_REACH` of an object.
        """
        _, s = self.store(thickness)
        return np.flatnonzero(within_reach(gap) & s.free)

    def prepare(self, gaps, thicknesses, progress: bool = True) -> int:
        """Solve the columns every sample (``gaps``, ``thicknesses`` ``(B, N)``, m) holds, one
        store per thickness; returns how many were solved (0: all cached).
        """
        by: dict[bytes, list] = {}
        for g, t in zip(np.asarray(gaps), np.asarray(thicknesses)):
            key, s = self.store(t)
            by.setdefault(key, []).append(g)
        n = 0
        for key, gs in by.items():
            s = self._stores[key]
            need = np.flatnonzero(within_reach(np.stack(gs)).any(0) & s.free)
            n += s.solve(need, progress)
        return n

    def _hold(self, key: bytes, store: SkinCompliance, H: np.ndarray):
        """The held set's DOFs and the Cholesky factor of ``G[H, H]`` (float64), kept."""
        k = (key, H.tobytes())
        if k not in self._holds:
            at = (H[:, None] * 3 + np.arange(3)).ravel()
            G = store.columns(H)
            A = torch.from_numpy(G[at].astype(np.float64))
            A = 0.5 * (A + A.T)
            L, info = torch.linalg.cholesky_ex(A)
            if int(info) != 0:  # float32 rounding of a nearly singular block: a tiny ridge
                ridge = 1e-7 * float(A.diagonal().mean())
                L = torch.linalg.cholesky(A + ridge * torch.eye(len(A), dtype=A.dtype))
            if len(self._holds) >= CACHED_HOLDS:
                self._holds.pop(next(iter(self._holds)))
            self._holds[k] = (torch.from_numpy(at), L)
        return self._holds[k]

    def _matrix(self, key: bytes, store: SkinCompliance, device) -> torch.Tensor:
        if key not in self._G:
            self._G[key] = torch.from_numpy(store.G)  # shares the store's memory
        return self._G[key].to(device)

    def __call__(self, r, gap, thickness):
        """``(B, N, 3)`` the skin held at ``r`` ``(B, N, 3)`` (any unit) on each sample's held
        vertices (``gap`` ``(B, N)``, m; ``thickness`` ``(B, N)``, m; torch), the linear FEM's
        answer elsewhere; zero where no object is near.
        """
        g = gap.detach().cpu().numpy()
        t = thickness.detach().cpu().numpy()
        out = []
        for b in range(len(r)):
            key, s = self.store(t[b])
            H = np.flatnonzero(within_reach(g[b]) & s.free)
            if len(H) == 0:
                out.append(torch.zeros_like(r[b]))
                continue
            at, L = self._hold(key, s, H)
            G = self._matrix(key, s, r.device)
            rh = r[b].reshape(-1)[at.to(r.device)].double()[:, None]
            f = torch.cholesky_solve(rh, L.to(r.device)).to(r.dtype)[:, 0]
            out.append((G.index_select(1, at.to(r.device)) @ f).reshape(r[b].shape))
        return torch.stack(out)


def fit_held(predictor, dataset, progress: bool = True) -> None:
    """Give ``predictor`` (option ``prior: held``) its :class:`HeldSkin` for ``dataset``'s part
    and tissue, with the columns every sample of the set holds solved (cached on disk), and
    record it in ``predictor.meta["holding"]``.
    """
    cfg = dataset.card["config"]
    tissue = cfg.get("tissue") or "paper"
    if tissue == "paper":
        raise ValueError(
            "prior: held carries the skin by a layered tissue's linear FEM; this dataset's is "
            "the paper's gel (take prior: contact)"
        )
    body = cfg.get("body") or {}
    skin = {"tissue": tissue, "phenotype": cfg.get("phenotype", body.get("phenotype"))}
    h = HeldSkin(predictor.part, **skin)
    a = dataset.arrays()
    own = a.get("body", np.zeros(len(a["thickness"]), int)) == 0
    if not own.all():
        raise ValueError("prior: held knows the linear FEM of the model's own body only")
    t0 = time.perf_counter()
    gaps = [
        of_sample(predictor.part.vertices, k, params, g)
        for k, params, g in zip(a["kind"], a["params"], a["gap"])
    ]
    solved = h.prepare(gaps, a["thickness"], progress)
    predictor.held_skin = h
    predictor.meta["holding"] = {
        "skin": skin,
        "reach_m": GAP_REACH,
        "columns_at_fit": int(solved),
        "compute_seconds": round(time.perf_counter() - t0, 3),
    }
