"""The linear FEM as a prior of a learned model (option ``prior``): the model holds a
:class:`~models.linear.operator.ComplianceOperator` as ``model.prior``, takes its answer as an
input (:data:`models.features.PRIOR_SCALE`) and learns only the correction to it.
"""

from __future__ import annotations

import numpy as np

from fem.compliance import ColumnStore
from models.features import CORRECTION_SCALE, HOLDING
from models.holding import HeldSkin, fit_held
from models.linear.operator import (
    ComplianceOperator,
    check_operator,
    fit_on_demand,
    fit_operator,
    install,
    needed_columns,
    reattach,
    solve_needed,
    unsolved,
)

PRIORS = ("none", "linear", "contact", "held", "closure")
"""``linear``: the linear FEM's answer to the force (:class:`LinearPrior`); ``contact``: of a
model given a pose, the skin inside the objects moved out to their surface
(:meth:`~models.learned.LearnedPredictor.contact_base`); ``held``: of a model given a pose, the
contact prior and the network's answer held near the objects and carried to the rest of the
skin by the tissue's linear FEM (:mod:`models.holding`); ``closure``: held likewise, with the
linear FEM's answer to the objects closing on the skin with friction in place of the contact
prior (:mod:`fem.closure`; a model given the objects' motion too)."""

HELD_ANSWERS = ("displacement", "force")
"""What a model with a held prior answers on the held skin (option ``held_answer``):
``displacement``, the skin's own, carried to the rest by the linear FEM holding it there
(:meth:`models.holding.HeldSkin.__call__`, a factor of the held block at each new held set);
``force`` (prior ``closure``), the held skin's displacement from the closure and forces on it,
which the compliance carries everywhere (:meth:`models.holding.HeldSkin.pushed`, no factor)."""

PRESSURE_START = 0.1
"""A pose model's contact pressure before it has learned (units of 10 kPa: 1 kPa, a light
touch's), :func:`start_silent`."""


def start_silent(last, posed: bool = False) -> None:
    """Zero a network's last layer ``last`` (a linear layer or a convolution, one output per
    channel), so that its answer starts as the prior's (the linear FEM's, the skin laid on the
    object, or the skin at rest) and Adam's first steps correct it rather than throw it far; a
    pose model's two pressure channels (``posed``) start at :data:`PRESSURE_START` (they are
    read from their logarithm). From a random start the first answers were tens of times the
    reaction, and the steps that brought them down left the pressures answering the same at
    every depth.
    """
    import torch  # deferred: about a second to import; the core's types do not need it

    with torch.no_grad():
        last.weight.zero_()
        last.bias.zero_()
        if posed:
            last.bias[3:5] = float(np.log(PRESSURE_START))


class LinearPrior:
    """Mixin for a :class:`LearnedPredictor` with the option ``prior`` (``none``, ``linear`` or
    ``contact``, which :meth:`~models.learned.LearnedPredictor.answered` adds)
    and ``operator`` (how the prior's operator travels, ``stored`` or ``on_demand``, see
    :data:`models.linear.operator.OPERATORS`):
    with ``linear`` its model holds a :class:`ComplianceOperator` as ``model.prior``,
    :meth:`fit` computes it from the dataset, :meth:`base` gives its answer and
    :meth:`corrected` adds the network's correction to it.
    """

    @classmethod
    def options(cls, config: dict | None = None) -> dict:
        out = super().options(config)
        if out["prior"] not in PRIORS:
            raise ValueError(f"prior must be one of {PRIORS}, got {out['prior']!r}")
        check_operator(out.get("operator", "stored"))
        if out.get("given") == "pose" and out["prior"] == "linear":
            raise ValueError(
                "the linear prior answers a force; a model given a pose takes prior: none, "
                "contact, held or closure"
            )
        if out["prior"] == "closure" and out.get("given") == "pose" and not out.get("motion"):
            raise ValueError(
                "the closure prior replays how the objects close: it needs motion: true"
            )
        if out.get("held_answer", "displacement") not in HELD_ANSWERS:
            raise ValueError(
                f"held_answer must be one of {HELD_ANSWERS}, got {out['held_answer']!r}"
            )
        if out.get("held_answer", "displacement") == "force" and out["prior"] != "closure":
            raise ValueError(
                "held_answer: force adds forces to the linear FEM's closure of the objects: it "
                "takes prior: closure"
            )
        if out.get("given") != "pose" and out["prior"] in ("contact", *HOLDING):
            raise ValueError(
                f"the {out['prior']} prior reads a posed object's gap; a model given a force "
                "takes prior: none or linear"
            )
        if out.get("geometry") and out["prior"] == "linear" and out["operator"] != "on_demand":
            raise ValueError(
                "a model of every body (geometry: true) with the linear prior "
                "needs operator: on_demand (the linear FEM is solved for each "
                "body it meets)"
            )
        return out

    @property
    def prior(self) -> bool:
        return self.config["prior"] == "linear"

    def fit(self, dataset, progress: bool = True) -> None:
        """With ``prior: linear``, compute the linear FEM operator for ``dataset`` (cached);
        with ``prior: held``, the skin's compliance near every sample's objects
        (:func:`models.holding.fit_held`).
        """
        if self.config["prior"] in HOLDING:
            fit_held(self, dataset, progress)
        elif self.prior and self.config.get("operator", "stored") == "on_demand":
            fit_on_demand(self, self.model.prior, dataset, {}, progress)
        elif self.prior:
            install(self, self.model.prior, fit_operator(self.part, dataset, {}, progress))

    def restored(self) -> None:
        if self.prior:
            reattach(self, self.model.prior)
        if self.config["prior"] in HOLDING:
            self.held_skin = HeldSkin(self.part, **self.meta["holding"]["skin"])

    def base(self, thickness, force, body=None, base=None):
        """The linear FEM's ``(B, N, 3)`` answer in the units of ``raw``, or None without the
        prior: ``base`` (m) if the caller has it, else solved on each sample's body (``body``
        ``(B,)`` slots; None: the model's own, :meth:`body_prior`).
        """
        if not self.prior:
            return None
        if base is not None:
            return self.normalised(base, force)
        return self.normalised(on_bodies(self, self.model.prior, thickness, force, body), force)

    def load_kernels(self) -> None:
        """The prior's solves' compiled code (:meth:`ComplianceOperator.load_kernels`), then the
        rest of the predictor's.
        """
        if self.prior:
            self.model.prior.load_kernels()
        super().load_kernels()

    def prepare(self, part, thickness, progress: bool = True) -> int:
        """Solve the prior's columns at every vertex of ``part`` for tissue ``thickness``
        (:func:`prepare_operator`); 0 without the prior or with a stored operator.
        """
        if not self.prior:
            return 0
        return prepare_operator(self, self.model.prior, part, thickness, progress)

    def missing(self, scene) -> int:
        """The prior's columns ``scene`` loads that are not yet solved
        (:func:`missing_columns`); 0 without the prior.
        """
        return missing_columns(self, self.model.prior, scene) if self.prior else 0

    def ahead(self, scenes) -> None:
        """Solve the columns a batch of ``scenes`` needs on each of their bodies at once, one
        solve per level (:func:`models.linear.operator.solve_needed`), before the batch is
        answered chunk by chunk.
        """
        if not self.prior:
            return
        by_body: dict = {}
        for s in scenes:
            by_body.setdefault(id(s.part), []).append(s)
        for group in by_body.values():
            op = _on_demand(self, self.model.prior, group[0].part)
            if op is None:
                continue
            t = np.stack([s.thickness for s in group]).astype(np.float32)
            f = np.stack([s.force for s in group]).astype(np.float32)
            if unsolved(op.store, op, needed_columns(op, t, f)):
                solve_needed(op.store, op, t, f, progress=False)

    def body_prior(self, k: int):
        """The linear FEM of body slot ``k`` (the model's own: ``model.prior``), on demand: a
        :class:`~fem.compliance.ColumnStore` for that body and the recorded FEM set-up, whose
        levels gain each uniform layer's thickness exactly (the linear answer there is then the
        FEM's, not interpolated, as the training data's ``linear`` was).
        """
        return self.model.prior if k == 0 else body_operator(self, k)

    @staticmethod
    def corrected(base, out):
        """The prior ``base`` plus the network's output ``out`` read as a correction (the
        output alone without a prior); any ``(..., 3)`` shapes that broadcast.
        """
        return out if base is None else base + CORRECTION_SCALE * out


def prepare_operator(predictor, own, part, thickness, progress: bool = True) -> int:
    """Solve into the disk cache every column of the on-demand linear FEM that a scene on
    ``part`` (the predictor's own body, operator ``own``, or another:
    :func:`body_operator`) with tissue ``thickness`` ``(N,)`` m can load: every vertex, at each
    level the thickness needs (one factorisation per level, with a progress bar). Returns how
    many columns were solved (0: all cached, or a stored operator that carries them all).
    """
    import torch  # deferred: about a second to import; the core's types do not need it

    op = _on_demand(predictor, own, part)
    if op is None:
        return 0
    t = np.asarray(thickness, dtype=np.float32)[None]
    if t.shape != (1, part.n_vertices) or not np.all(np.isfinite(t)):
        raise ValueError(f"thickness must be ({part.n_vertices},) finite values in m")
    with torch.no_grad():
        return solve_needed(op.store, op, t, np.ones_like(t), progress)


def missing_columns(predictor, own, scene) -> int:
    """How many columns of the on-demand linear FEM (``own``, the predictor's own operator, or
    another body's: :func:`body_operator`) ``scene`` loads that are not yet solved; 0 for a
    stored operator (it carries them all).
    """
    op = _on_demand(predictor, own, scene.part)
    if op is None:
        return 0
    t = np.asarray(scene.thickness, dtype=np.float32)[None]
    f = np.asarray(scene.force, dtype=np.float32)[None]
    return unsolved(op.store, op, needed_columns(op, t, f))


def _on_demand(predictor, own, part):
    """The on-demand linear FEM of ``part``'s body (``own`` for the predictor's own), or None
    when the operator is stored (it carries every column).
    """
    k = predictor.slot(part)
    op = own if k == 0 else body_operator(predictor, k)
    return op if op.on_demand else None


def on_bodies(predictor, own, thickness, force, body=None):
    """``(B, N, 3)`` m: the linear FEM's answer of each sample on its own body: ``own`` (the
    operator of the predictor's own part) for slot 0 or ``body`` None, :func:`body_operator`
    for the others, each body's samples in one call.
    """
    if body is None or not bool((body != 0).any()):
        return own(thickness, force)
    import torch  # deferred: about a second to import; the core's types do not need it

    u = torch.zeros(*force.shape, 3, device=force.device)
    for k in torch.unique(body).tolist():
        at = torch.nonzero(body == k).flatten()
        op = own if k == 0 else body_operator(predictor, k)
        u[at] = op(thickness[at], force[at])
    return u


def body_operator(predictor, k: int):
    """The on-demand linear FEM operator of ``predictor``'s body slot ``k``: a
    :class:`~fem.compliance.ColumnStore` for that body's part and the FEM set-up the predictor's
    own operator records (``meta["operator"]``), exact at each uniform layer's thickness; made
    once per body and kept.
    """
    ops = predictor.__dict__.setdefault("_body_operators", {})
    if k not in ops:
        meta = predictor.meta.get("operator") or {}
        if meta.get("mode") != "on_demand":
            raise ValueError(
                f"{predictor.name}: the linear FEM of another body needs the "
                "on-demand operator (operator: on_demand)"
            )
        op = ComplianceOperator()
        op.attach(
            ColumnStore(
                predictor.body_parts[k], meta["setup"], [float(x) * 1e-3 for x in meta["levels_mm"]]
            )
        )
        op.exact = True
        ops[k] = op.to(predictor.device)
    return ops[k]
