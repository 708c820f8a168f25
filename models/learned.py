"""The machinery every torch model shares: the base class (its network built and called, the
loss, forward in normalised units), compilation, and checkpoint writing and reading; on the
torch-free half of :class:`models.trained.TrainedPredictor`. The models
(``models/<kind>/predictor.py``) implement only their network and its inputs.
"""

from __future__ import annotations

import time
import warnings

import numpy as np
import torch
import torch.nn.functional as F

from models.compiled import TOLERANCE, compile_module, uncompiled
from models.features import (
    CONTACT_BAND,
    HOLDING,
    MIN_TOTAL_N,
    PRESSURE_OUT_SCALE,
    contact_weight,
    gap_of,
    posed_answer,
    pressure_out,
    squeezes,
    total_force,
)
from models.losses import log_near_loss, near_loss, pooled_loss, relative_loss
from models.trained import TrainedPredictor, checkpoint_part
from stmpl import checkpoint, loads, tissue
from stmpl.contact import objects
from stmpl.contact.posing import posed
from stmpl.reach import REGION_TOLERANCE
from stmpl.scene import Scene


def torch_device(name):
    """``torch.device(name)`` if this machine has it; else ``ValueError`` naming it."""
    try:
        dev = torch.device(name)
    except (RuntimeError, TypeError) as e:
        raise ValueError(f"unknown device {name!r}; use cpu, cuda, cuda:N or mps") from e
    if dev.type == "cuda" and not torch.cuda.is_available():
        raise ValueError(f"device {name} is not available: this machine has no CUDA")
    return dev


class LearnedPredictor(TrainedPredictor):
    """A predictor with a torch model trained on FEM data, for one body part (or, with the
    option ``geometry``, for every body of that part's mesh: see :meth:`bodies_of`).

    Subclasses set ``kind`` and implement :meth:`build_model` and :meth:`raw`; they may
    override :meth:`loss`. With the option ``per_newton`` the network predicts the displacement
    per newton of the scene's total force and :meth:`forward` multiplies it back. A checkpoint
    stores the model's tensors and the part's arrays, so it rebuilds the predictor with nothing
    else.
    """

    def __init__(
        self,
        part,
        config: dict | None = None,
        device: str = "cpu",
        fidelity: str = "full",
        region_tolerance: float = REGION_TOLERANCE,
    ):
        super().__init__(part, config, fidelity, region_tolerance)
        self.device = torch_device(device)
        self.model = self.build_model().to(self.device)
        self.slot(part)  # the model's own body is slot 0

    def body_tensors(self, part) -> dict:
        """The per-body tensors the network's inputs need, for ``part`` (one body of the
        mesh): vertex areas' inverse ``inv_area`` ``(N,)`` (1/m^2) and ``normals`` ``(N, 3)``.
        Subclasses add their own.
        """

        def t(x):
            return torch.tensor(np.asarray(x), dtype=torch.float32, device=self.device)

        return {"inv_area": t(1.0 / part.vertex_areas), "normals": t(part.normals)}

    def bodies_of(self, parts) -> "torch.Tensor":
        """``(B,)`` slots of the scenes' parts (:meth:`slot`)."""
        return torch.tensor([self.slot(p) for p in parts], dtype=torch.long, device=self.device)

    def body_tensor(self, name: str, body) -> "torch.Tensor":
        """``(B, ...)``: the per-body tensor ``name`` of each sample's body (``body`` ``(B,)``
        slots).
        """
        if name not in self._stacked:
            self._stacked[name] = torch.stack([d[name] for d in self._body_data])
        return self._stacked[name].index_select(0, body)

    # -- to implement
    def build_model(self):
        raise NotImplementedError

    def raw(self, thickness, force, body=None, base=None):
        """The network's ``(B, N, 3)`` output from ``thickness`` ``(B, N)`` (m) and ``force``
        ``(B, N)`` (N), torch tensors on ``self.device``: the displacement in units of
        ``self.scale`` (m), or with ``per_newton`` in units of ``self.scale`` per newton of
        the scene's total force. ``body``: ``(B,)`` slots of the samples' bodies
        (:meth:`slot`; None: the model's own); ``base``: a prior's answer ``(B, N, 3)`` in m
        when the caller has it (a dataset's ``linear``).
        """
        raise NotImplementedError

    def forward(self, thickness, force, body=None, base=None):
        """``(B, N, 3)`` displacement in units of ``self.scale`` (m)."""
        return self.denormalised(self.answered(thickness, force, body, base), force)

    def answered(self, thickness, force, body=None, base=None):
        """:meth:`raw` with a pose model's pressures read (:meth:`with_pressures`), the
        contact prior added (option ``prior: contact`` or ``held``) or the linear FEM's
        closure (``closure``: :meth:`closure_base`), and the skin held (``held`` and
        ``closure``: :meth:`held`); with ``held_answer: force`` the network answers, beside
        the held skin's displacement from the closure, forces on it, which the compliance
        carries everywhere (:meth:`models.holding.HeldSkin.pushed`: no factor).
        """
        out = self.raw(thickness, force, body, base)
        forces = None
        if self.config.get("held_answer") == "force":
            out, forces = out[..., :5], out[..., 5:]
        out = self.with_pressures(out)
        prior = self.config.get("prior")
        if prior not in HOLDING and prior != "contact":
            return out
        if prior == "closure":
            near = self.closure_base(force, thickness, body)
        else:
            near = self.contact_base(gap_of(force), body)
        if self.config.get("held_answer") == "force":  # the network's: forces on the held skin
            pushed = self.held_skin_of(body).pushed(out[..., :3], forces, gap_of(force), thickness)
            return torch.cat([near + pushed, out[..., 3:]], -1)
        out = out + F.pad(near, (0, out.shape[-1] - 3))
        if prior == "contact":
            return out
        return torch.cat(
            [self.held(out[..., :3], gap_of(force), thickness, body), out[..., 3:]], -1
        )

    def held_skin_of(self, body=None):
        """The model's :class:`models.holding.HeldSkin` (priors ``held`` and ``closure``),
        refused where it was not fitted or a sample lies on another body (``body`` ``(B,)``).
        """
        skin = getattr(self, "held_skin", None)
        prior = self.config.get("prior")
        what = f"prior: {prior}" if prior else "the closure"
        if skin is None:
            raise ValueError(
                f"{self.name}: {what} needs the skin's linear FEM, made by fitting the model to "
                "its dataset (stmpl train) or read with its checkpoint"
            )
        if body is not None and bool((body != 0).any()):
            raise ValueError(f"{self.name}: {what} knows the linear FEM of its own body only")
        return skin

    def held(self, r, gap, thickness, body=None):
        """The held prior (:mod:`models.holding`): the skin held at ``r`` ``(B, N, 3)`` near
        the objects, the tissue's linear FEM elsewhere.
        """
        return self.held_skin_of(body)(r, gap, thickness)

    def closure_base(self, given, thickness, body=None):
        """The closure prior (option ``prior: closure``, a model given a pose and its motion)
        ``(B, N, 3)`` in the units of :meth:`raw`: the skin as the objects close on it with
        friction, answered by the tissue's linear FEM (:meth:`fem.holding.HeldSkin.closure`;
        the friction coefficient and the objects' rounding are the training set's). Not
        differentiated: it depends on the scene alone.
        """
        skin = self.held_skin_of(body)
        if given.ndim != 3:
            raise ValueError(f"{self.name}: prior: closure reads the way the objects move")
        kept = getattr(self, "_closure_kept", None)  # an answer reads it twice: input and prior
        if kept is not None and kept[0] is given and kept[1] is thickness and kept[2] is body:
            if kept[3] == (given._version, thickness._version):
                return kept[4]
        g = given.detach().cpu().numpy()
        t = thickness.detach().cpu().numpy()
        closing = self.closure_options()
        out = np.stack(
            [skin.closure(g[b, :, 0], g[b, :, 1:4], t[b], *closing) for b in range(len(g))]
        )
        out = torch.from_numpy(out).to(given.device, given.dtype) / self.scale
        self._closure_kept = (given, thickness, body, (given._version, thickness._version), out)
        return out

    def with_pressures(self, out):
        """A network's output ``(..., C)`` with a pose model's two pressure channels read from
        their logarithm (:func:`~models.features.pressure_out`); a force model's as it is.
        """
        if not self.posed:
            return out
        return torch.cat([out[..., :3], pressure_out(out[..., 3:])], -1)

    def contact_base(self, gap, body=None):
        """The contact prior (option ``prior: contact``, a model given a pose) ``(B, N, 3)`` in
        the units of :meth:`raw`: each rest skin vertex inside an object (``gap`` ``(B, N)``, m,
        negative there) moved out to the object's surface along its inward normal, zero
        elsewhere. Under a press the skin lies on the object's face, so the prior gives the
        dent where the object touches and the network learns the rest: the dent round it, the
        skin's slip along the face and the contact pressure.
        """
        if body is None:
            normals = self._body_data[0]["normals"][None]
        else:
            normals = self.body_tensor("normals", body)
        return normals * gap.clamp_max(0.0)[..., None] / self.scale

    def denormalised(self, r, force):
        """Network output ``(B, ..., 3)`` in the units of :meth:`raw` -> units of ``self.scale``
        (the inverse of :meth:`normalised` without the scale).
        """
        return r * total_force(force)[:, None, None] if self.per_newton else r

    def normalised(self, target, force):
        """The target ``(B, N, 3)`` (m) in the units of :meth:`raw`; of a pose model ``(B, N,
        5)``: the displacement (m), the contact pressure and its push along the press (Pa).
        """
        if self.posed:
            return torch.cat(
                [target[..., :3] / self.scale, target[..., 3:] / PRESSURE_OUT_SCALE], -1
            )
        t = target / self.scale
        if self.per_newton:
            t = t / total_force(force).clamp_min(MIN_TOTAL_N)[:, None, None]
        return t

    def loss(self, thickness, force, target, body=None, base=None):
        """Training loss for a batch; ``target`` ``(B, N, 3)`` in m. Option ``loss``: ``mse``
        (default, the paper's L2), the mean squared error over the vertices of :meth:`raw`
        against the normalised target (with ``per_newton`` each sample's error counts per
        newton, so a light press weighs as much as a heavy one); ``relative``, each sample's
        mean Euclidean error over its peak displacement (the relative MEE the targets use);
        ``pooled``, the batch's mean Euclidean errors over its peaks, summed before the ratio
        (:func:`pooled_loss`: heavier presses weigh more). A pose model (``force`` then the gap
        field, ``target`` the displacement, the contact pressure and its push, :meth:`normalised`)
        adds, where the object presses (:func:`near_loss`: over the whole part a dent of a few
        vertices weighs next to nothing; an answer's contact force lives there alone), the
        displacement's relative error, the pressures' in their logarithm (:func:`log_near_loss`),
        and the reaction's (:meth:`reaction_loss`); the option ``displacement_weight`` weighs the
        displacement's two terms against the pressures' (a relative MEE of a few per cent is
        small beside the pressures' logarithmic errors, and a grip's displacement learned little
        at weight 1).
        """
        pred, tgt = self.answered(thickness, force, body, base), self.normalised(target, force)
        if self.config.get("loss", "mse") == "mse":
            return ((pred - tgt) ** 2).mean()
        if self.posed:  # where the object presses: the dent, the pressures; the reaction
            gap = gap_of(force)
            p, t, near = pred[..., 3:], tgt[..., 3:], gap <= CONTACT_BAND
            pressure = log_near_loss(p, t, near) + self.reaction_loss(p, t, gap, body)
            dent = near_loss(pred[..., :3], tgt[..., :3], near)
            shape = self.euclidean_loss(pred[..., :3], tgt[..., :3], force) + dent
            return float(self.config.get("displacement_weight", 1.0)) * shape + pressure
        return self.euclidean_loss(pred, tgt, force)

    def reaction_loss(self, pred, tgt, gap, body=None):
        """A pose model's reaction error beside a ``relative`` or ``pooled`` loss: from ``(B, N,
        2)`` contact pressure and push per vertex (units of :meth:`raw`) and the gap field ``gap``
        ``(B, N)`` (m), the mean over the samples of ``|log(R / R*)|``, the reaction ``R`` the
        push summed over the vertex areas weighed by :func:`~models.features.contact_weight`,
        as an answer sums it, and ``R*`` the true one: the relative error where it is
        small, and an answer ten times too large pulled back by a bounded step (each vertex by
        its share of ``R``), not by ten times the step. Beside it the pressures' error where the
        object presses keeps their map in shape.
        """
        inv_area = (
            self._body_data[0]["inv_area"][None]
            if body is None
            else self.body_tensor("inv_area", body)
        )
        k = self.reaction_channel
        true = (tgt[..., k] / inv_area).sum(-1)
        got = contact_weight(gap) * pred[..., k] / inv_area
        return (
            (torch.log(got.sum(-1).clamp_min(1e-12)) - torch.log(true.clamp_min(1e-12)))
            .abs()
            .mean()
        )

    @property
    def reaction_channel(self) -> int:
        """Which of a pose model's pressure channels its reaction sums (option ``reaction``,
        :data:`models.trained.REACTIONS`): 1, the push, or 0, the pressure.
        """
        return 0 if squeezes(self.config) else 1

    def euclidean_loss(self, pred, tgt, force):
        """The ``relative`` or ``pooled`` loss of ``(B, N, 3)`` outputs against targets in the
        units of :meth:`raw` (``pooled`` weighs per-newton samples by their total force).
        """
        if self.config["loss"] == "relative":
            return relative_loss(pred, tgt)
        return pooled_loss(pred, tgt, total_force(force) if self.per_newton else None)

    def predict_batch(self, scenes) -> list[np.ndarray]:
        if self.model.training:
            self.model.eval()
        return super().predict_batch(scenes)

    def _answers(self, scenes) -> list:
        """:meth:`predict_batch` of one network call."""
        t = torch.tensor(
            np.stack([s.thickness for s in scenes]), dtype=torch.float32, device=self.device
        )
        f = torch.tensor(self.given(scenes), dtype=torch.float32, device=self.device)
        body = None
        if self.general and any(s.part is not self.part for s in scenes):
            body = self.bodies_of([s.part for s in scenes])
        with torch.no_grad():
            out = self.forward(t, f, body)
        u = list((out[..., :3] * self.scale).double().cpu().numpy())
        if not self.posed:
            return u
        pressures = out[..., 3:].double().cpu().numpy() * PRESSURE_OUT_SCALE
        squeeze = squeezes(self.config)
        return [
            posed_answer(s, x, p[:, 0], p[:, 1], squeeze) for s, x, p in zip(scenes, u, pressures)
        ]

    def network(self) -> torch.nn.Module:
        """The module :meth:`compile` compiles: the network without its prior (by default the
        whole model).
        """
        return self.model

    def compile(self, scene: Scene | None = None) -> float:
        """Compile the network (:func:`models.compiled.compile_module`) and answer ``scene``
        both ways, at this predictor's fidelity (default scene: a 1.5 cm disk of 0.2 N on
        7.5 mm at the vertex nearest the part's centre; of a pose model, an 8 mm ball 2 mm into
        the skin there). Returns the seconds the compiled answer
        took (the compilation). A compiled answer farther than
        :data:`models.compiled.TOLERANCE` of the deepest displacement from the eager one, or a
        compilation that fails, leaves the network eager and raises ``RuntimeError``.
        """
        net = self.network()
        if scene is None:
            part = self.part
            at = int(np.argmin(np.linalg.norm(part.vertices - part.vertices.mean(0), axis=1)))
            t = tissue.constant(part, 0.0075)
            if self.posed:  # an 8 mm ball 2 mm into the skin there
                ball = objects.sphere(0.008)
                scene = posed(part, t, ball, objects.press(part, ball, at, depth=0.002))
            else:
                scene = Scene.from_load(part, t, loads.disk(part, at, radius=0.015, total=0.2))
        with warnings.catch_warnings():  # the warm-up scene's place in the envelope is moot
            warnings.simplefilter("ignore")
            eager = self.predict(scene).displacement
            compile_module(net)
            t0 = time.perf_counter()
            try:
                fast = self.predict(scene).displacement
            except Exception as e:  # Inductor's failures (no compiler, a kernel) vary
                uncompiled(net)
                first = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
                raise RuntimeError(
                    f"{self.name}: the network could not be compiled: {first}"
                ) from e
        seconds = time.perf_counter() - t0
        deepest = float(np.linalg.norm(eager, axis=1).max())
        off = float(np.abs(fast - eager).max())
        if off > TOLERANCE * max(deepest, 1e-12):
            uncompiled(net)
            raise RuntimeError(
                f"{self.name}: the compiled network answers {off * 1e3:.3g} mm from the eager one "
                f"(deepest {deepest * 1e3:.3g} mm, tolerance {TOLERANCE:g} of it): left eager"
            )
        return seconds

    def n_parameters(self) -> int:
        return sum(p.numel() for p in self.model.parameters())

    def save(self, path, meta: dict | None = None):
        """Write a checkpoint (``.safetensors`` + sidecar) with ``meta`` (card hash, metrics)."""
        tensors = {f"model.{k}": v for k, v in self.model.state_dict().items()}
        for k, v in self.part.arrays().items():
            tensors[f"part.{k}"] = torch.as_tensor(np.asarray(v))
        side = {
            "kind": self.name,
            "config": self.config,
            "part": self.part.name,
            "part_source": self.part.source,
            "disp_scale_m": self.scale,
            "parameters": self.n_parameters(),
            **self.meta,
            **(meta or {}),
        }
        if self.envelope is not None:
            side["envelope"] = self.envelope.to_dict()
        return checkpoint.write(path, tensors, side)

    @classmethod
    def from_checkpoint(cls, path, device: str = "cpu", **options):
        """The predictor a checkpoint holds, on ``device``; ``options`` (``fidelity``,
        ``region_tolerance``) go to the constructor.
        """
        tensors, meta = checkpoint.read(path)
        if meta["kind"] != cls.name:
            raise ValueError(f"checkpoint {path} holds a {meta['kind']!r} model, not {cls.name!r}")
        part = checkpoint_part(path, {k: v.numpy() for k, v in tensors.items()}, meta)
        p = cls(part, meta["config"], device=device, **options)
        state = {k[6:]: v for k, v in tensors.items() if k.startswith("model.")}
        try:
            p.model.load_state_dict(state)
        except RuntimeError as e:
            raise ValueError(f"checkpoint {path} does not fit its model config: {e}") from e
        p.restore(path, meta)
        return p
