"""One interface for everything that turns a :class:`~stmpl.scene.Scene` into a
:class:`~stmpl.scene.Deformation`: the FEM (ground truth), the paper's Naive baseline, the UV-UNet
and the mesh GNN.

>>> p = stmpl.predictor.create("fem", res="medium")
>>> d = p.predict(scene)                 # one Deformation
>>> ds = p.predict([scene_a, scene_b])   # a list, same order

Learned predictors also load from a checkpoint: ``Predictor.from_checkpoint(path)`` or
``stmpl.predictor.load(path)`` (the checkpoint names its kind).
"""

from __future__ import annotations

import time
from typing import Protocol, Sequence, runtime_checkable

import numpy as np

from stmpl.scene import Deformation, Scene


@runtime_checkable
class Predictor(Protocol):
    """What every predictor offers."""

    name: str

    def predict(self, scenes: Scene | Sequence[Scene]) -> Deformation | list[Deformation]:
        """A Deformation for a scene, or a list of them for a sequence of scenes."""
        ...


REGISTRY: dict[str, type] = {}


def register(name: str):
    """Class decorator: make a predictor creatable by ``name``."""

    def deco(cls):
        if name in REGISTRY and REGISTRY[name] is not cls:
            raise ValueError(f"predictor name {name!r} is taken by {REGISTRY[name].__name__}")
        REGISTRY[name] = cls
        cls.name = name
        return cls

    return deco


def _import_models() -> None:
    """Learned predictors register themselves when their package is imported."""
    import importlib

    for mod in ("models.naive", "models.linear", "models.uv_unet", "models.gnn"):
        try:
            importlib.import_module(mod)
        except ImportError as e:  # a model whose optional dependency is missing
            if mod in str(e):
                raise


def names() -> list[str]:
    """Registered predictor names."""
    _import_models()
    return sorted(REGISTRY)


def get(name: str) -> type:
    """The predictor class registered as ``name``."""
    _import_models()
    if name not in REGISTRY:
        raise ValueError(f"unknown predictor {name!r}; known: {sorted(REGISTRY)}")
    return REGISTRY[name]


def create(name: str, *args, **kwargs) -> "BasePredictor":
    """A predictor by registered name (learned ones take the body part first)."""
    return get(name)(*args, **kwargs)


def load(path, device: str = "cpu") -> "BasePredictor":
    """A learned predictor from its checkpoint (the sidecar names the kind)."""
    from stmpl.checkpoint import read_sidecar

    _import_models()
    kind = read_sidecar(path)["kind"]
    if kind not in REGISTRY:
        raise ValueError(f"checkpoint {path} is of unknown kind {kind!r}")
    return REGISTRY[kind].from_checkpoint(path, device=device)


class BasePredictor:
    """Shared plumbing: single or batch input, validation, timing in ``Deformation.info``.

    Subclasses implement :meth:`predict_batch` on a non-empty list of scenes and return one
    ``(N, 3)`` displacement (m) per scene."""

    name = "base"

    def predict(self, scenes: Scene | Sequence[Scene]) -> Deformation | list[Deformation]:
        single = isinstance(scenes, Scene)
        batch = [scenes] if single else list(scenes)
        if not batch:
            raise ValueError("predict needs at least one scene")
        for i, s in enumerate(batch):
            if not isinstance(s, Scene):
                raise TypeError(f"scene {i} is a {type(s).__name__}, not a Scene")
        self.check(batch)
        t0 = time.perf_counter()
        out = self.predict_batch(batch)
        dt = (time.perf_counter() - t0) / len(batch)
        result = []
        for s, u in zip(batch, out):
            u = np.asarray(u, dtype=float)
            if not np.all(np.isfinite(u)):
                raise FloatingPointError(f"{self.name} predicted non-finite displacements")
            result.append(Deformation(s, u, {"predictor": self.name, "seconds": dt,
                                             **self.info(s)}))
        return result[0] if single else result

    def check(self, scenes: list[Scene]) -> None:
        """Raise if the predictor cannot take these scenes (e.g. another body part)."""

    def info(self, scene: Scene) -> dict:
        return {}

    def predict_batch(self, scenes: list[Scene]) -> list[np.ndarray]:
        raise NotImplementedError


class FEMFailed(RuntimeError):
    """The FEM could not solve a scene; the message says why."""


@register("fem")
class FEMPredictor(BasePredictor):
    """The ground truth as a predictor: the tissue-shell FEM (see :mod:`fem`).

    Args:
        res: mesh resolution name or :class:`fem.simulate.Resolution` (default the reference).
        levels: continuation levels from rest to each scene's force.
        material, options: passed to the solver.
    A failed solve raises :class:`FEMFailed` (never a displacement).
    """

    def __init__(self, res="reference", levels: int = 1, material=None, options=None):
        from fem.simulate import resolution

        self.res = resolution(res)
        if int(levels) != levels or levels < 1:
            raise ValueError(f"levels must be an integer >= 1, got {levels!r}")
        self.levels, self.material, self.options = int(levels), material, options
        self._last: dict = {}

    def predict_batch(self, scenes: list[Scene]) -> list[np.ndarray]:
        from fem.simulate import simulate

        out = []
        for s in scenes:
            total = float(s.force.sum())
            if total <= 0:
                out.append(np.zeros((s.part.n_vertices, 3)))
                self._last[id(s)] = {"fem": "no load"}
                continue
            totals = total * np.arange(1, self.levels + 1) / self.levels
            mesh, sols = simulate(s.part, s.thickness, s.force, totals, self.res, self.material,
                                  self.options)
            sol = sols[-1]
            if not sol.ok:
                raise FEMFailed(f"FEM failed at {sol.total_force:.3g} N: {sol.reason}")
            self._last[id(s)] = {k: v for k, v in sol.diagnostics().items() if k != "reason"}
            out.append(sol.part_displacement(mesh))
        return out

    def info(self, scene: Scene) -> dict:
        return {"resolution": self.res.to_dict(), **self._last.pop(id(scene), {})}


DISP_SCALE_MM = 10.0
"""Default displacement normalisation, mm: [-10, 10] mm maps to [-1, 1]. The paper's 30 mm
suits its 1..10 N; the forces E = 1 kPa tissue can carry give at most a few mm, and a UNet's
tanh output squeezed into 1/10 of its range learns the far field poorly. Every learned model
takes it as the option ``disp_scale_mm``; the checkpoint keeps it."""


LOSSES = ("mse", "relative")
LOSS_EPS = 1e-6
"""Regularises the ``relative`` loss's norms (units of :meth:`LearnedPredictor.raw`, so about
1e-6 of the full scale, well under any error that counts)."""


def relative_loss(pred, target):
    """Mean over samples of ``mean_i |pred_i - target_i| / max_i |target_i|`` for ``(B, N, 3)``
    tensors: the relative MEE, smooth at zero error (``LOSS_EPS``)."""
    import torch

    norm = torch.sqrt(((pred - target) ** 2).sum(-1) + LOSS_EPS ** 2)      # (B, N)
    peak = target.norm(dim=-1).amax(-1)                                    # (B,)
    return (norm.mean(-1) / (peak + LOSS_EPS)).mean()


MIN_TOTAL_N = 1e-9
"""N: below this total force a scene is unloaded; a per-newton model's inputs are then zero."""


def total_force(force):
    """``(B,)`` total force (N) of ``(B, N)`` per-vertex force magnitudes (torch)."""
    return force.sum(-1)


def force_pattern(force):
    """``(B, N)`` per-vertex force divided by the scene's total (1 where loaded alone; zero for
    an unloaded scene), torch."""
    return force / total_force(force).clamp_min(MIN_TOTAL_N)[:, None]


class LearnedPredictor(BasePredictor):
    """A predictor with a torch model trained on FEM data, for one body part.

    Subclasses set ``kind`` and implement :meth:`build_model` and :meth:`raw`; they may
    override :meth:`loss`. With the option ``per_newton`` the network predicts the displacement
    per newton of the scene's total force and :meth:`forward` multiplies it back. A checkpoint
    stores the model's tensors and the part's arrays, so it rebuilds the predictor with nothing
    else.
    """

    defaults: dict = {}

    def __init__(self, part, config: dict | None = None, device: str = "cpu"):
        import torch

        self.part = part
        self.config = self.options(config)
        self.per_newton = bool(self.config.get("per_newton", False))
        self.scale = float(self.config["disp_scale_mm"]) * 1e-3
        self.device = torch.device(device)
        self.model = self.build_model().to(self.device)
        self.meta: dict = {}

    @classmethod
    def options(cls, config: dict | None = None) -> dict:
        """The model options ``config`` over the defaults, checked (unknown keys, the loss, the
        displacement scale) without building anything; raises ``ValueError``."""
        allowed = {**cls.defaults, "disp_scale_mm": DISP_SCALE_MM}
        unknown = set(config or {}) - set(allowed)
        if unknown:
            raise ValueError(f"unknown {cls.name} model options {sorted(unknown)}; allowed: "
                             f"{sorted(allowed)}")
        out = {**allowed, **(config or {})}
        if out.get("loss", "mse") not in LOSSES:
            raise ValueError(f"loss must be one of {LOSSES}, got {out['loss']!r}")
        if not float(out["disp_scale_mm"]) > 0:
            raise ValueError(f"disp_scale_mm must be > 0, got {out['disp_scale_mm']}")
        return out

    # -- to implement
    def build_model(self):
        raise NotImplementedError

    def raw(self, thickness, force):
        """The network's ``(B, N, 3)`` output from ``thickness`` ``(B, N)`` (m) and ``force``
        ``(B, N)`` (N), torch tensors on ``self.device``: the displacement in units of
        ``self.scale`` (m), or with ``per_newton`` in units of ``self.scale`` per newton of
        the scene's total force."""
        raise NotImplementedError

    def forward(self, thickness, force):
        """``(B, N, 3)`` displacement in units of ``self.scale`` (m)."""
        return self.denormalised(self.raw(thickness, force), force)

    def denormalised(self, r, force):
        """Network output ``(B, ..., 3)`` in the units of :meth:`raw` -> units of ``self.scale``
        (the inverse of :meth:`normalised` without the scale)."""
        return r * total_force(force)[:, None, None] if self.per_newton else r

    def normalised(self, target, force):
        """The target ``(B, N, 3)`` (m) in the units of :meth:`raw`."""
        t = target / self.scale
        if self.per_newton:
            t = t / total_force(force).clamp_min(MIN_TOTAL_N)[:, None, None]
        return t

    def loss(self, thickness, force, target):
        """Training loss for a batch; ``target`` ``(B, N, 3)`` in m. Option ``loss``: ``mse``
        (default, the paper's L2), the mean squared error over the vertices of :meth:`raw`
        against the normalised target (with ``per_newton`` each sample's error counts per
        newton, so a light press weighs as much as a heavy one); ``relative``, each sample's
        mean Euclidean error over its peak displacement (the relative MEE the targets use)."""
        pred, tgt = self.raw(thickness, force), self.normalised(target, force)
        if self.config.get("loss", "mse") == "mse":
            return ((pred - tgt) ** 2).mean()
        return relative_loss(pred, tgt)

    # -- shared
    def check(self, scenes) -> None:
        for i, s in enumerate(scenes):
            if s.part.n_vertices != self.part.n_vertices or not np.allclose(
                    s.part.vertices, self.part.vertices, atol=1e-6):
                raise ValueError(f"scene {i} is on another body part ({s.part.name}, "
                                 f"{s.part.n_vertices} vertices) than this {self.name} predictor "
                                 f"was trained on ({self.part.name}, {self.part.n_vertices})")

    def predict_batch(self, scenes) -> list[np.ndarray]:
        import torch

        t = torch.tensor(np.stack([s.thickness for s in scenes]), dtype=torch.float32,
                         device=self.device)
        f = torch.tensor(np.stack([s.force for s in scenes]), dtype=torch.float32,
                         device=self.device)
        self.model.eval()
        with torch.no_grad():
            u = self.forward(t, f) * self.scale
        return list(u.double().cpu().numpy())

    def n_parameters(self) -> int:
        return sum(p.numel() for p in self.model.parameters())

    def save(self, path, meta: dict | None = None):
        """Write a checkpoint (``.safetensors`` + sidecar) with ``meta`` (card hash, metrics)."""
        import torch

        from stmpl import checkpoint

        tensors = {f"model.{k}": v for k, v in self.model.state_dict().items()}
        for k, v in self.part.arrays().items():
            tensors[f"part.{k}"] = torch.as_tensor(np.asarray(v))
        side = {"kind": self.name, "config": self.config, "part": self.part.name,
                "part_source": self.part.source, "disp_scale_m": self.scale,
                "parameters": self.n_parameters(), **self.meta, **(meta or {})}
        return checkpoint.save(path, tensors, side)

    @classmethod
    def from_checkpoint(cls, path, device: str = "cpu"):
        from stmpl import checkpoint
        from stmpl.body.part import BodyPart

        tensors, meta = checkpoint.load(path)
        if meta["kind"] != cls.name:
            raise ValueError(f"checkpoint {path} holds a {meta['kind']!r} model, not "
                             f"{cls.name!r}")
        arrays = {k[5:]: v.numpy() for k, v in tensors.items() if k.startswith("part.")}
        part = BodyPart.from_arrays(meta["part"], arrays, meta.get("part_source"))
        p = cls(part, meta["config"], device=device)
        state = {k[6:]: v for k, v in tensors.items() if k.startswith("model.")}
        try:
            p.model.load_state_dict(state)
        except RuntimeError as e:
            raise ValueError(f"checkpoint {path} does not fit its model config: {e}") from e
        p.meta = {k: v for k, v in meta.items() if k not in ("config", "kind")}
        return p
