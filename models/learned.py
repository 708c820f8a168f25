"""The machinery every learned predictor shares: the base class (options, loss, forward in
normalised units, prediction in batches), the losses, and checkpoint writing and reading. The
models (``models/<kind>/model.py``) implement only their network and its inputs.
"""

from __future__ import annotations

import time
import warnings

import numpy as np
import torch
import torch.nn.functional as F

from fem.layers import bound as tissue_bound
from models.compiled import TOLERANCE, compile_module, uncompiled
from models.features import (
    CONTACT_BAND,
    MIN_TOTAL_N,
    PRESSURE_OUT_SCALE,
    posed_answer,
    pressure_out,
    total_force,
)
from models.losses import log_near_loss, near_loss, pooled_loss, relative_loss
from stmpl import checkpoint, loads, tissue
from stmpl import config as checked
from stmpl.body.mirror import MIRROR, mirror_twin, mirrored_scene
from stmpl.contact import objects
from stmpl.contact.posing import posed
from stmpl.data.dataset import same_mesh
from stmpl.envelope import Envelope
from stmpl.part import BodyPart, difference
from stmpl.predictor import BasePredictor, check_fidelity
from stmpl.reach import REGION_TOLERANCE
from stmpl.scene import Deformation, Scene
from stmpl.tissue import Bound

DISP_SCALE_MM = 10.0
"""Default displacement normalisation, mm: [-10, 10] mm maps to [-1, 1]. The paper's 30 mm
suits its 1..10 N; the forces E = 1 kPa tissue can carry give at most a few mm, and a UNet's
tanh output squeezed into 1/10 of its range learns the far field poorly. Every learned model
takes it as the option ``disp_scale_mm``; the checkpoint keeps it."""


CHUNK_VERTICES = 8192
"""A batch at fidelity ``full`` is answered in calls of about this many vertices
(:meth:`LearnedPredictor.chunk`)."""
CHUNK_SCENES = 32
"""A batch at fidelity ``auto`` is answered in calls of this many scenes."""

LOSSES = ("mse", "relative", "pooled")
GIVEN = ("force", "pose")
"""What a learned model takes (option ``given``): the force on the skin, or an object's pose
(the gap field; it then answers the contact pressure as well, :mod:`stmpl.pose`)."""


def torch_device(name):
    """``torch.device(name)`` if this machine has it; else ``ValueError`` naming it."""
    try:
        dev = torch.device(name)
    except (RuntimeError, TypeError) as e:
        raise ValueError(f"unknown device {name!r}; use cpu, cuda, cuda:N or mps") from e
    if dev.type == "cuda" and not torch.cuda.is_available():
        raise ValueError(f"device {name} is not available: this machine has no CUDA")
    return dev


class LearnedPredictor(BasePredictor):
    """A predictor with a torch model trained on FEM data, for one body part (or, with the
    option ``geometry``, for every body of that part's mesh: see :meth:`bodies_of`).

    Subclasses set ``kind`` and implement :meth:`build_model` and :meth:`raw`; they may
    override :meth:`loss`. With the option ``per_newton`` the network predicts the displacement
    per newton of the scene's total force and :meth:`forward` multiplies it back. A checkpoint
    stores the model's tensors and the part's arrays, so it rebuilds the predictor with nothing
    else.
    """

    defaults: dict = {}
    counts: tuple = ()
    """The options that are counts (integers >= 1): a network's width, depth, steps..."""
    poses = False
    """Whether the model can be given an object's pose (option ``given: pose``)."""

    def __init__(
        self,
        part,
        config: dict | None = None,
        device: str = "cpu",
        fidelity: str = "full",
        region_tolerance: float = REGION_TOLERANCE,
    ):
        self.part = part
        self._fidelity = check_fidelity(fidelity)
        self.region_tolerance = float(region_tolerance)
        """``fidelity="auto"``: the network answers where the prior moves the tissue by more
        than this share of its deepest (:func:`stmpl.reach.moved`)."""
        self.config = self.options(config)
        self.takes = (self.config["given"],)
        self.per_newton = bool(self.config.get("per_newton", False))
        self.scale = float(self.config["disp_scale_mm"]) * 1e-3
        self.device = torch_device(device)
        self._slots: dict = {}
        self.body_parts: list = []
        self._body_data: list[dict] = []
        self._stacked: dict = {}
        self.model = self.build_model().to(self.device)
        self.meta: dict = {}
        self.slot(part)  # the model's own body is slot 0

    @classmethod
    def options(cls, config: dict | None = None) -> dict:
        """The model options ``config`` over the defaults, checked (unknown keys, the loss, the
        displacement scale) without building anything; raises ``ValueError``.
        """
        allowed = {**cls.defaults, "disp_scale_mm": DISP_SCALE_MM, "given": "force"}
        unknown = set(config or {}) - set(allowed)
        if unknown:
            raise ValueError(
                f"unknown {cls.name} model options {sorted(unknown)}; allowed: {sorted(allowed)}"
            )
        out = {**allowed, **(config or {})}
        if out.get("loss", "mse") not in LOSSES:
            raise ValueError(f"loss must be one of {LOSSES}, got {out['loss']!r}")
        checked.number(out["disp_scale_mm"], "disp_scale_mm", 0, low_open=True, unit="mm")
        if out["given"] not in GIVEN:
            raise ValueError(f"given must be one of {GIVEN}, got {out['given']!r}")
        if out["given"] == "pose" and not cls.poses:
            raise ValueError(f"the {cls.name} model takes a force only (given: force)")
        if out["given"] == "pose" and out.get("per_newton"):
            raise ValueError("a model given a pose knows no force to answer per newton of")
        for key in cls.counts:
            checked.integer(out[key], key, 1)
        return out

    @property
    def posed(self) -> bool:
        """Whether the model takes an object's pose (option ``given: pose``): its input is the
        gap field, and its outputs the displacement, the contact pressure and its push along
        the press (the reaction's density).
        """
        return self.config["given"] == "pose"

    @property
    def out_channels(self) -> int:
        """The network's outputs per vertex: the displacement, and for a pose the contact
        pressure and its part along the press direction (the reaction's density).
        """
        return 5 if self.posed else 3

    # -- bodies
    any_body = False
    """Let a model of one body answer on other bodies of its mesh (their own areas, normals,
    edge offsets and linear FEM as inputs, where the model has them): what a model trained on
    one body is worth on others, the first point of a learning curve over bodies
    (``benchmarks/bodies.py``). Off by default: such a model refuses another body."""

    @property
    def general(self) -> bool:
        """Whether the model serves every body of its part's mesh (option ``geometry``: the
        body's shape is an input; or :attr:`any_body`), not only the body it was built on.
        """
        return bool(self.config.get("geometry", False)) or self.any_body

    def body_tensors(self, part) -> dict:
        """The per-body tensors the network's inputs need, for ``part`` (one body of the
        mesh): vertex areas' inverse ``inv_area`` ``(N,)`` (1/m^2) and ``normals`` ``(N, 3)``.
        Subclasses add their own.
        """

        def t(x):
            return torch.tensor(np.asarray(x), dtype=torch.float32, device=self.device)

        return {"inv_area": t(1.0 / part.vertex_areas), "normals": t(part.normals)}

    def slot(self, part) -> int:
        """The index of ``part``'s body among those met (added, its tensors computed, the first
        time: the model's own part is slot 0).
        """
        key = getattr(self, "_last_slot", (None, None))
        if key[0] is part:
            return key[1]
        digest = part.vertices.tobytes()
        k = self._slots.get(digest)
        if k is None:
            if self.body_parts:
                why = same_mesh(part, self.part)
                if why:
                    raise ValueError(f"another mesh than this {self.name} model's: {why}")
                if not self.general and difference(part, self.part):
                    raise ValueError(
                        f"another body than this {self.name} model's: {difference(part, self.part)}"
                    )
            k = self._slots[digest] = len(self.body_parts)
            self.body_parts.append(part)
            self._body_data.append(self.body_tensors(part))
            self._stacked = {}
        self._last_slot = (part, k)
        return k

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
        """:meth:`raw` with a pose model's pressures read (:meth:`with_pressures`) and the
        contact prior added (option ``prior: contact``).
        """
        out = self.with_pressures(self.raw(thickness, force, body, base))
        if self.config.get("prior") != "contact":
            return out
        return out + F.pad(self.contact_base(force, body), (0, out.shape[-1] - 3))

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
        and the reaction's (:meth:`reaction_loss`).
        """
        pred, tgt = self.answered(thickness, force, body, base), self.normalised(target, force)
        if self.config.get("loss", "mse") == "mse":
            return ((pred - tgt) ** 2).mean()
        if self.posed:  # where the object presses: the dent, the pressures; the reaction
            p, t, near = pred[..., 3:], tgt[..., 3:], force <= CONTACT_BAND
            pressure = log_near_loss(p, t, near) + self.reaction_loss(p, t, force, body)
            dent = near_loss(pred[..., :3], tgt[..., :3], near)
            return self.euclidean_loss(pred[..., :3], tgt[..., :3], force) + dent + pressure
        return self.euclidean_loss(pred, tgt, force)

    def reaction_loss(self, pred, tgt, gap, body=None):
        """A pose model's reaction error beside a ``relative`` or ``pooled`` loss: from ``(B, N,
        2)`` contact pressure and push per vertex (units of :meth:`raw`) and the gap field ``gap``
        ``(B, N)`` (m), the mean over the samples of ``|log(R / R*)|``, the reaction ``R`` the
        push summed over the vertex areas within :data:`~models.features.CONTACT_BAND` of the
        object, as an answer sums it, and ``R*`` the true one: the relative error where it is
        small, and an answer ten times too large pulled back by a bounded step (each vertex by
        its share of ``R``), not by ten times the step. Beside it the pressures' error where the
        object presses keeps their map in shape.
        """
        inv_area = (
            self._body_data[0]["inv_area"][None]
            if body is None
            else self.body_tensor("inv_area", body)
        )
        true = (tgt[..., 1] / inv_area).sum(-1)
        got = torch.where(gap <= CONTACT_BAND, pred[..., 1], 0.0) / inv_area
        return (
            (torch.log(got.sum(-1).clamp_min(1e-12)) - torch.log(true.clamp_min(1e-12)))
            .abs()
            .mean()
        )

    def euclidean_loss(self, pred, tgt, force):
        """The ``relative`` or ``pooled`` loss of ``(B, N, 3)`` outputs against targets in the
        units of :meth:`raw` (``pooled`` weighs per-newton samples by their total force).
        """
        if self.config["loss"] == "relative":
            return relative_loss(pred, tgt)
        return pooled_loss(pred, tgt, total_force(force) if self.per_newton else None)

    @property
    def bound(self) -> Bound:
        """How far an answer may compress the tissue of the data it learned from
        (:attr:`tissue`; :func:`fem.layers.bound`). A tissue that is no preset (a file of
        layers, which the data's card names but does not hold) has no muscle depth to count
        here: its answers are not judged by compression (their envelope still bounds them).
        """
        try:
            return tissue_bound(self.tissue)
        except ValueError:
            return Bound(np.inf, 0.0, "thickness", f"(tissue {self.tissue!r} is no preset)")

    def restored(self) -> None:
        """Called when a checkpoint has been loaded (``self.meta`` set): rebuild what the
        checkpoint does not carry. Nothing by default.
        """

    # -- shared
    def predict(self, scenes, strict: bool | None = None):
        """As :meth:`BasePredictor.predict`; a scene on the mirror twin of the model's part
        (anny's right arm for a model of the left: :func:`stmpl.part.mirror_twin`) is
        answered in the mirror: its loads and thickness on the mirrored mesh, the displacement
        mirrored back (``info["mirrored"]``).
        """
        single = isinstance(scenes, Scene)
        batch = [scenes] if single else list(scenes)
        twins = [mirror_twin(s.part, self.part) if isinstance(s, Scene) else None for s in batch]
        if not any(t is not None for t in twins):
            return super().predict(scenes, strict)
        seen = [s if t is None else mirrored_scene(s, t) for s, t in zip(batch, twins)]
        out = super().predict(seen, strict)
        back = [
            d
            if t is None
            else Deformation(
                s, d.displacement * MIRROR, {**d.info, "mirrored": True}, d.force, d.reaction
            )
            for s, t, d in zip(batch, twins, out)
        ]
        return back[0] if single else back

    def outside(self, scenes) -> list[list[str]]:
        """As :meth:`BasePredictor.outside`; a pose also lies outside where its objects reach
        deeper into the rest skin than any training pose did (``meta["pose_deepest_mm"]``).
        """
        out = super().outside(scenes)
        deepest = self.meta.get("pose_deepest_mm")
        for i, s in enumerate(scenes):
            reach = 0.0 if s.pose is None else -1e3 * float(s.pose.gap.min())
            if deepest is not None and reach > deepest + 0.05:
                out[i] = out[i] + [
                    f"its object reaches {reach:.2f} mm into the skin at rest, deeper than any "
                    f"pose in the data ({deepest:.2f} mm)"
                ]
        return out

    def check(self, scenes) -> None:

        for i, s in enumerate(scenes):
            if s.part is self.part or s.part is getattr(self, "_checked_part", None):
                continue  # the same object as last time: same mesh
            if self.general:
                why = same_mesh(s.part, self.part)
                if why:
                    raise ValueError(
                        f"scene {i} is on another mesh than this {self.name} "
                        f"predictor serves (any body of its {self.part.name}): "
                        f"{why}"
                    )
            else:
                why = difference(s.part, self.part)
                if why:
                    hint = (
                        "; a model of every body (option geometry: true) serves it"
                        if not same_mesh(s.part, self.part)
                        else ""
                    )
                    raise ValueError(
                        f"scene {i} is on another body part than this "
                        f"{self.name} predictor was trained on: {why}{hint}"
                    )
            self._checked_part = s.part

    def chunk(self) -> int:
        """How many scenes one network call answers: a bigger batch is answered in chunks of
        this many. A call's temporaries grow with its graph or images, and past a few megabytes
        each operation runs from memory instead of cache: on this project's 2-core machine the
        time per scene was lowest at about :data:`CHUNK_VERTICES` vertices a call over the
        whole part (``fidelity="full"``: 3 scenes of the 2109-vertex arm) and at about
        :data:`CHUNK_SCENES` scenes at ``"auto"`` (their regions are a few hundred vertices).
        """
        if self.fidelity == "auto":
            return CHUNK_SCENES
        return max(1, CHUNK_VERTICES // self.part.n_vertices)

    def predict_batch(self, scenes) -> list[np.ndarray]:
        if self.model.training:
            self.model.eval()
        n = self.chunk()
        if len(scenes) > n:
            self.ahead(scenes)
        out = []
        for k in range(0, len(scenes), n):
            out += self._answers(scenes[k : k + n])
        return out

    def ahead(self, scenes) -> None:
        """Compute at once what every chunk of a batch would compute on its own (a linear
        prior's columns: one solve for the batch, not one per chunk). Nothing by default.
        """

    def _answers(self, scenes) -> list:
        """:meth:`predict_batch` of one network call."""
        t = torch.tensor(
            np.stack([s.thickness for s in scenes]), dtype=torch.float32, device=self.device
        )
        given = [s.pose.gap if self.posed else s.force for s in scenes]
        f = torch.tensor(np.stack(given), dtype=torch.float32, device=self.device)
        body = None
        if self.general and any(s.part is not self.part for s in scenes):
            body = self.bodies_of([s.part for s in scenes])
        with torch.no_grad():
            out = self.forward(t, f, body)
        u = list((out[..., :3] * self.scale).double().cpu().numpy())
        if not self.posed:
            return u
        pressures = out[..., 3:].double().cpu().numpy() * PRESSURE_OUT_SCALE
        return [posed_answer(s, x, p[:, 0], p[:, 1]) for s, x, p in zip(scenes, u, pressures)]

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
        arrays = {k[5:]: v.numpy() for k, v in tensors.items() if k.startswith("part.")}
        part = BodyPart.from_arrays(meta["part"], arrays, meta.get("part_source"))
        p = cls(part, meta["config"], device=device, **options)
        state = {k[6:]: v for k, v in tensors.items() if k.startswith("model.")}
        try:
            p.model.load_state_dict(state)
        except RuntimeError as e:
            raise ValueError(f"checkpoint {path} does not fit its model config: {e}") from e
        p.meta = {k: v for k, v in meta.items() if k not in ("config", "kind", "envelope")}
        p.tissue = meta.get("dataset", {}).get("tissue", "paper")
        p.restored()
        if "envelope" in meta:
            try:
                p.envelope = Envelope.from_dict(meta["envelope"])
            except ValueError as e:
                raise ValueError(f"checkpoint {path}: {e}") from e
        return p
