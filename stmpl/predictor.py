"""One interface for everything that turns a :class:`~stmpl.scene.Scene` into a
:class:`~stmpl.scene.Deformation`, and the registry that finds the implementations.

>>> p = stmpl.predictor.create("fem", res="medium")
>>> d = p.predict(scene)                 # one Deformation
>>> ds = p.predict([scene_a, scene_b])   # a list, same order
>>> q = stmpl.predictor.read("runs/gnn/gnn.safetensors")   # a trained one, from its checkpoint

The core knows no implementation. Predictors plug in as Python entry points of the group
``stmpl.predictors`` (the FEM in ``fem``, the learned models in ``models``; see
``pyproject.toml``), found when a name is first asked for; :func:`register` adds one at run time.
"""

from __future__ import annotations

import copy
import time
import warnings
from importlib.metadata import entry_points
from typing import Protocol, Sequence, runtime_checkable

import numpy as np

from stmpl import tissue
from stmpl.checkpoint import read_sidecar
from stmpl.failures import ImpossibleAnswer, OutsideEnvelope, PredictionFailed
from stmpl.fidelity import check_fidelity
from stmpl.scene import Deformation, Scene

GROUP = "stmpl.predictors"
"""The entry-point group predictors are declared in."""


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


def _declared() -> dict:
    """The entry points of :data:`GROUP` by name."""
    return {ep.name: ep for ep in entry_points(group=GROUP)}


def names() -> list[str]:
    """Names of every predictor: declared as entry points or registered at run time."""
    return sorted(set(_declared()) | set(REGISTRY))


def get(name: str) -> type:
    """The predictor class called ``name`` (its entry point is imported on first use)."""
    if name not in REGISTRY:
        declared = _declared()
        ep = declared.get(name)
        if ep is None:
            hint = (
                ""
                if declared
                else (
                    " (no predictor is declared: install stmpl, e.g. "
                    "`pip install -e .`, so its entry points exist)"
                )
            )
            raise ValueError(f"unknown predictor {name!r}; known: {names()}{hint}")
        cls = ep.load()
        REGISTRY.setdefault(name, cls)
        cls.name = name
    return REGISTRY[name]


def create(name: str, *args, **kwargs) -> "BasePredictor":
    """A predictor by name (learned ones take the body part first)."""
    return get(name)(*args, **kwargs)


NUMPY = "stmpl.numpy"
"""Entry points of the predictors' NumPy inference, by kind: a trained model answered without
its training library (torch), for one-off answers that should not pay its import."""

ENGINES = ("default", "numpy", "auto")
"""How :func:`read` answers a checkpoint: with its kind's own class, with the kind's NumPy
inference (refused for a kind that has none), or the NumPy one where the kind has it and the
device is the CPU."""


def read(path, device: str = "cpu", engine: str = "default", **options) -> "BasePredictor":
    """A trained predictor from its checkpoint file (the checkpoint names its kind);
    ``engine``: one of :data:`ENGINES`; ``options`` (e.g. ``fidelity``) go to its constructor.
    """
    if engine not in ENGINES:
        raise ValueError(f"engine must be one of {ENGINES}, got {engine!r}")
    kind = read_sidecar(path)["kind"]
    if kind not in names():
        raise ValueError(f"checkpoint {path} is of unknown kind {kind!r}; known: {names()}")
    light = {ep.name: ep for ep in entry_points(group=NUMPY)}
    if engine == "numpy" and kind not in light:
        raise ValueError(f"a {kind} model has no NumPy inference; those that do: {sorted(light)}")
    if engine == "numpy" or (engine == "auto" and kind in light and device == "cpu"):
        cls = light[kind].load()
        cls.name = kind
        return cls.from_checkpoint(path, device=device, **options)
    return get(kind).from_checkpoint(path, device=device, **options)


class BasePredictor:
    """Shared plumbing: single or batch input, validation, timing in ``Deformation.info``.

    Subclasses implement :meth:`predict_batch` on a non-empty list of scenes and return one
    ``(N, 3)`` displacement (m) per scene; for a scene given by a pose (a predictor whose
    :attr:`takes` has ``"pose"``), a dict of its ``displacement``, ``force`` ``(N,)`` (N) and
    ``reaction`` (N).
    """

    name = "base"
    takes: tuple = ("force",)
    """What scenes the predictor answers: given by their ``"force"``, by an object's ``"pose"``
    (:attr:`stmpl.scene.Scene.given`), or both. Any other is refused by name."""
    envelope = None
    """The :class:`~stmpl.envelope.Envelope` of the data behind the answers, or ``None`` (the
    FEM, which fails loudly instead)."""
    strict = False
    """Refuse scenes outside the envelope (``PredictionFailed``) instead of warning."""
    tissue = "paper"
    """The tissue the answers are for: ``"paper"`` (the gel) or a layered preset's name (or a
    file of layers; a learned model's is its data's)."""
    friction = None
    """Coulomb's coefficient between posed objects and the skin in the data behind the answers
    (a learned model's: its data's, where it records one), or ``None``."""
    batched = True
    """Whether a batch of scenes costs less per scene than one at a time. ``False`` for the FEM,
    which solves them one after the other in seconds each and may fail on one alone: callers
    that measure (evaluation, latency) then give it one scene at a time."""
    _fidelity = "full"

    @property
    def bound(self) -> tissue.Bound:
        """How far an answer may compress the tissue (:class:`stmpl.tissue.Bound`): the gel's
        here; a predictor of layered tissue gives its preset's.
        """
        return tissue.GEL

    @property
    def fidelity(self) -> str:
        """``"full"`` models the whole part; ``"auto"`` only what the scene needs (the FEM: the
        patch the load moves; the GNN: the subgraph around it), where the predictor can (others
        ignore it). Given at construction (see :data:`FIDELITIES`); :meth:`with_fidelity` gives
        a predictor of another fidelity.
        """
        return self._fidelity

    def forget_scenes(self) -> None:
        """Forget what was kept of the scenes answered (not what serves every scene of the
        body), so that the next answer to a scene costs what a new scene's does: a timed call
        after a warm-up measures that. Nothing is kept by default.
        """

    def with_fidelity(self, fidelity: str) -> "BasePredictor":
        """A copy of this predictor (sharing its model and caches) at ``fidelity``."""
        other = copy.copy(self)
        other._fidelity = check_fidelity(fidelity)
        return other

    def predict(
        self, scenes: Scene | Sequence[Scene], strict: bool | None = None
    ) -> Deformation | list[Deformation]:
        """A Deformation per scene. Scenes outside the predictor's envelope are answered with
        ``info["envelope"]["inside"] = False`` and one :class:`OutsideEnvelope` warning per
        call; with ``strict`` (default: the predictor's ``strict``) they raise
        ``PredictionFailed`` before anything is predicted.
        """
        single = isinstance(scenes, Scene)
        if not single and not hasattr(scenes, "__iter__"):
            raise TypeError(
                f"predict takes a Scene or a list of Scenes, got {type(scenes).__name__}"
            )
        batch = [scenes] if single else list(scenes)
        if not batch:
            raise ValueError("predict needs at least one scene")
        for i, s in enumerate(batch):
            if not isinstance(s, Scene):
                raise TypeError(f"scene {i} is a {type(s).__name__}, not a Scene")
            if s.given not in self.takes:
                raise ValueError(_refusal(self, i, s.given))
        self.check(batch)
        strict = self.strict if strict is None else strict
        outside = self.outside(batch)
        self._judge(outside, strict)
        t0 = time.perf_counter()
        out = self.predict_batch(batch)
        dt = (time.perf_counter() - t0) / len(batch)
        if self.envelope is not None and any(s.pose is not None for s in batch):
            # a posed scene: where the contact its answer describes lies among the data's
            answered = [
                self.envelope.reasons(part=s.part, thickness=s.thickness, force=u["force"])
                if s.pose is not None
                else []
                for s, u in zip(batch, out)
            ]
            self._judge(answered, strict, "the contact it answers lies")
            outside = [a or b for a, b in zip(outside, answered)]
        result, bound = [], self.bound
        for s, u, why in zip(batch, out, outside):
            answer = u if isinstance(u, dict) else {"displacement": u}
            u = np.asarray(answer["displacement"], dtype=float)
            if not np.all(np.isfinite(u)):
                raise PredictionFailed(f"{self.name} predicted non-finite displacements")
            inward = -np.einsum("ij,ij->i", u, s.part.normals)
            compression = bound.of(inward, s.thickness)
            impossible = _impossible(s, answer, compression, bound)
            for reason in impossible:
                warnings.warn(
                    f"{self.name}: {reason}: no answer to trust", ImpossibleAnswer, stacklevel=2
                )
            result.append(
                Deformation(
                    s,
                    u,
                    {
                        "predictor": self.name,
                        "seconds": dt,
                        "max_compression": compression,
                        "physical": not impossible,
                        "impossible": impossible,
                        "envelope": None
                        if self.envelope is None
                        else {"inside": not why, "outside": why},
                        **self.info(s),
                    },
                    answer.get("force"),
                    answer.get("reaction"),
                )
            )
        return result[0] if single else result

    def _judge(self, outside: list[list[str]], strict: bool, what: str = "") -> None:
        """Warn once (:class:`OutsideEnvelope`) when a scene lies outside the envelope, or with
        ``strict`` refuse (:class:`PredictionFailed`); ``outside``: per scene, why.
        """
        bad = [i for i, why in enumerate(outside) if why]
        if not bad:
            return
        n = len(outside)
        which = f"{len(bad)} of {n} scenes lie" if n > 1 else "the scene lies"
        if what:
            which = f"for {len(bad)} of {n} scenes {what}" if n > 1 else what
        msg = f"{self.name}: {which} outside the data its answers are backed by: " + "; ".join(
            outside[bad[0]]
        )
        if strict:
            raise PredictionFailed(msg + " (strict: refused)")
        warnings.warn(msg, OutsideEnvelope, stacklevel=3)

    def outside(self, scenes: list[Scene]) -> list[list[str]]:
        """Per scene, why it lies outside :attr:`envelope` (``[]`` inside or without one). A
        scene given by a pose is judged by its answer instead: whether the contact the answer
        describes (its contact forces, the data's as the FEM answered them) lies inside.
        """
        if self.envelope is None:
            return [[] for _ in scenes]
        return [self.envelope.reasons(s) if s.pose is None else [] for s in scenes]

    def check(self, scenes: list[Scene]) -> None:
        """Raise if the predictor cannot take these scenes (e.g. another body part)."""

    def info(self, scene: Scene) -> dict:
        return {}

    def prepare(self, part, thickness, progress: bool = True) -> int:
        """Do, once and ahead, whatever a scene on ``part`` (a body part) with tissue
        ``thickness`` ``(N,)`` m needs before its first answer, so that no press waits for it
        (a linear FEM prior: its columns at every vertex, solved and cached on disk). Returns how
        many pieces it computed (0: nothing to do, or all cached). Nothing here by default.
        """
        return 0

    def load_kernels(self) -> None:
        """Load whatever compiled code makes many answers faster (a loop, a viewer, an
        evaluation), a cost of some tenths of a second once per process that a one-off answer
        does not pay back; the answers stay the same. Nothing here by default.
        """

    def missing(self, scene: Scene) -> int:
        """How many pieces (a linear FEM prior's columns) an answer to ``scene`` would compute
        before it answers: 0 when it answers at once, as by default.
        """
        return 0

    def predict_batch(self, scenes: list[Scene]) -> list[np.ndarray]:
        raise NotImplementedError


def _refusal(predictor, i: int, given: str) -> str:
    """Why ``predictor`` refuses scene ``i``, given by its ``given`` (force or pose)."""
    if given == "pose":
        return (
            f"{predictor.name} answers a force given on the skin, and scene {i} gives an "
            "object's pose (its force is what is asked): use a predictor that takes a pose, "
            "the FEM or a model trained on pressed objects"
        )
    return (
        f"{predictor.name} answers an object's pose, and scene {i} gives a force on the skin: "
        "use a predictor that takes a force"
    )


def given_to(predictor) -> str:
    """How a scene must be given to ``predictor`` (any object; a :class:`BasePredictor`'s
    :attr:`~BasePredictor.takes`): ``"pose"`` when it takes no force, else ``"force"``.
    """
    return "force" if "force" in getattr(predictor, "takes", ("force",)) else "pose"


def _impossible(scene: Scene, answer: dict, compression: float, bound: tissue.Bound) -> list[str]:
    """Why an answer cannot be true (empty when nothing says so), each reason one clause: skin
    pushed inward past the tissue's ``bound`` (``compression``: :meth:`~stmpl.tissue.Bound.of`
    the answer); for a posed scene, an object that reaches into the skin yet carries no force,
    or one that pulls.
    """
    why = []
    if compression > bound.compression:
        why.append(bound.reason(compression))
    if scene.pose is None:
        return why
    reaction, total = answer["reaction"], float(np.sum(answer["force"]))
    if reaction < 0:
        why.append(f"the object pulls on the skin ({reaction:.3g} N)")
    elif scene.pose.depth > 0 and (total <= 0 or reaction <= 0):
        why.append(
            f"the object reaches {1e3 * scene.pose.depth:.2f} mm into the skin yet the answer "
            "carries no force"
        )
    return why
