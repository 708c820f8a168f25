"""Precomputed linear FEM as a predictor: the compliance operator of the tissue shell
(:mod:`models.linear.operator`) applied to the load, ``u_i = sum_j G_ij(t_j) F_j``. No training:
it is computed from the dataset's own body part, material, resolution and solver options at a
few thickness levels and interpolated linearly between them. Exact for light loads; as strains
grow the Neo-Hookean tissue stiffens and the linear answer overshoots (the learned models may
take it as a prior and learn the rest, :mod:`models.prior`).

Its tensors are buffers, so a checkpoint carries the operator: sparse, the pairs ``(i, j)``
whose response reaches ``tol`` of the largest at some level.

Given a pose (options ``given: pose, motion: true``) it answers the linear FEM's closure: the
objects closing on the skin from first touch with the data's friction, the skin's compliance
near them solved once per thickness and cached (:meth:`fem.holding.HeldSkin.closed`), with the
contact forces that closure puts on the skin; the reaction is their normal part summed (a grip's
squeeze). What the learned models' closure prior starts from, answered alone.
"""

from __future__ import annotations

import numpy as np
from torch import nn

from models.holding import HeldSkin, fit_held
from models.learned import LearnedPredictor
from models.linear.operator import (
    ComplianceOperator,
    check_operator,
    fit_on_demand,
    fit_operator,
    install,
    reattach,
)
from models.prior import missing_columns, on_bodies, prepare_operator


class LinearPredictor(LearnedPredictor):
    """Precomputed linear FEM. Options: ``levels_mm`` (thickness levels, default the dataset's),
    ``tol`` (sparsity: entries below this share of the largest are dropped), ``operator``
    (``stored``: every column computed at fit time and carried by the checkpoint;
    ``on_demand``: the columns a scene loads, solved when first needed on the patch they move and
    cached on disk). :meth:`fit` computes the operator from a dataset; it has no trained
    parameters.
    """

    name = "linear"
    defaults = {"levels_mm": None, "tol": 1e-3, "operator": "stored"}
    poses = True

    @classmethod
    def options(cls, config: dict | None = None) -> dict:
        out = super().options(config)
        lv = out["levels_mm"]
        if lv is not None and not (
            isinstance(lv, (list, tuple))
            and len(lv) > 0
            and all(isinstance(x, (int, float)) and x > 0 for x in lv)
        ):
            raise ValueError(f"levels_mm must be a non-empty list of thicknesses in mm, got {lv!r}")
        if not (isinstance(out["tol"], (int, float)) and 0 <= out["tol"] < 1):
            raise ValueError(f"tol must be in [0, 1), got {out['tol']!r}")
        check_operator(out["operator"])
        if out["given"] == "pose":
            if not out["motion"]:
                raise ValueError(
                    "the linear FEM given a pose replays how the objects close: it needs "
                    "motion: true"
                )
            force_only = [k for k in cls.defaults if out[k] != cls.defaults[k]]
            if force_only:
                raise ValueError(
                    f"{force_only} shape the linear FEM of a force; given a pose it answers "
                    "the closure of the skin's compliance, solved on demand"
                )
        return out

    def build_model(self) -> nn.Module:
        op = ComplianceOperator()
        op.extend = self.config["operator"] == "on_demand"  # a new thickness: a new level
        return op

    @property
    def general(self) -> bool:
        """On demand, the linear FEM is solved for whatever body a scene is on."""
        return self.config["operator"] == "on_demand"

    def raw(self, thickness, force, body=None, base=None):

        return on_bodies(self, self.model, thickness, force, body) / self.scale

    def fit(self, dataset, progress: bool = True) -> None:
        """Compute the operator for ``dataset``'s part and FEM set-up (on demand: the columns
        the dataset's samples load).
        """
        if self.posed:
            fit_held(self, dataset, progress)
        elif self.config["operator"] == "on_demand":
            fit_on_demand(self, self.model, dataset, self.config, progress)
        else:
            install(self, self.model, fit_operator(self.part, dataset, self.config, progress))

    def restored(self) -> None:
        reattach(self, self.model)
        if self.posed:
            self.held_skin = HeldSkin(self.part, **self.meta["holding"]["skin"])

    def _answers(self, scenes) -> list:
        """Given a force, the operator's answers; given a pose, the closure's displacement, the
        normal contact force it puts on each vertex (N) and their sum, the reaction.
        """
        if not self.posed:
            return super()._answers(scenes)
        self.given(scenes)  # a pose without its way is refused by name
        skin = self.held_skin_of()
        closing = self.closure_options()
        out = []
        for s in scenes:
            u, f = skin.closed(s.pose.gap, s.pose.way, s.thickness, *closing)
            force = np.maximum(-np.einsum("ij,ij->i", f, s.part.normals), 0.0)
            out.append(
                {
                    "displacement": u.astype(np.float64),
                    "force": force,
                    "reaction": float(force.sum()),
                }
            )
        return out

    def load_kernels(self) -> None:
        """The compiled code of the operator's solves on demand
        (:meth:`ComplianceOperator.load_kernels`).
        """
        self.model.load_kernels()

    def missing(self, scene) -> int:
        """The operator's columns ``scene`` loads that are not yet solved (0 when stored)."""
        return missing_columns(self, self.model, scene)

    def prepare(self, part, thickness, progress: bool = True) -> int:
        """Solve the operator's columns at every vertex of ``part`` for tissue ``thickness``
        (:func:`~models.prior.prepare_operator`); 0 when stored (all carried).
        """
        return prepare_operator(self, self.model, part, thickness, progress)
