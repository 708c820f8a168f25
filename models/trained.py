"""The half of a trained predictor that needs no network library: its options, the bodies it
serves, the mirror, the envelope and the checks, and answering a batch in chunks. The torch
models (:class:`models.learned.LearnedPredictor`) and the NumPy inference of a trained GNN
(:class:`models.gnn.arrays.GNNArrays`) are both built on it, so a one-off answer need not import
torch.
"""

from __future__ import annotations

import numpy as np

from fem.layers import bound as tissue_bound
from stmpl import config as checked
from stmpl.body.mirror import MIRROR, mirror_twin, mirrored_scene
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


REACTIONS = ("push", "pressure")
"""A pose model's option ``reaction``: where its reaction comes from. ``push``: its push
channel summed (the pressure's part along the press direction, the reaction's density);
``pressure``: its contact forces summed (objects closing each along its own path, a grip, whose
reaction is the whole contact force, the squeeze, and whose push is the pressure itself), so
that the answer's contact forces sum to its reaction; the reaction's loss reads that channel."""


class TrainedPredictor(BasePredictor):
    """A predictor trained on FEM data, for one body part (or, with the option ``geometry``, for
    every body of that part's mesh: see :meth:`slot`), whatever runs its network.

    Subclasses implement :meth:`body_tensors` (the per-body inputs) and :meth:`_answers` (one
    network call's answers) and call :meth:`slot` on their own part at the end of their set-up.
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
        self._slots: dict = {}
        self.body_parts: list = []
        self._body_data: list[dict] = []
        self._stacked: dict = {}
        self.meta: dict = {}

    @classmethod
    def options(cls, config: dict | None = None) -> dict:
        """The model options ``config`` over the defaults, checked (unknown keys, the loss, the
        displacement scale) without building anything; raises ``ValueError``.
        """
        allowed = {**cls.defaults, "disp_scale_mm": DISP_SCALE_MM, "given": "force"}
        if cls.poses:
            allowed["motion"] = False
            allowed["displacement_weight"] = 1.0
            allowed["reaction"] = "push"
            allowed["held_answer"] = "displacement"
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
        if out.get("motion", False) not in (True, False):
            raise ValueError(f"motion must be true or false, got {out['motion']!r}")
        if out.get("motion") and out["given"] != "pose":
            raise ValueError(
                "motion: true reads the way a posed object moves; a model given a force has none"
            )
        checked.number(out.get("displacement_weight", 1.0), "displacement_weight", 0, low_open=True)
        if out.get("displacement_weight", 1.0) != 1.0 and out["given"] != "pose":
            raise ValueError(
                "displacement_weight weighs a pose model's displacement against its pressures; "
                "a model given a force answers no pressures"
            )
        if out.get("reaction", "push") not in REACTIONS:
            raise ValueError(f"reaction must be one of {REACTIONS}, got {out['reaction']!r}")
        if out.get("reaction", "push") != "push" and out["given"] != "pose":
            raise ValueError(
                "reaction says where a pose model's reaction comes from; a model "
                "given a force answers none"
            )
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
    def motion(self) -> bool:
        """Whether a pose model also reads the way the objects move (option ``motion``: the
        pose's :attr:`~stmpl.pose.Pose.way` field beside its gap): a grip's fingers sweep along
        the skin as they close, and friction drags the skin their way.
        """
        return bool(self.config.get("motion", False))

    def given(self, scenes) -> np.ndarray:
        """``(B, N)`` what the network reads of each scene: its force (N per vertex), or a
        pose's gap field (m); with the option ``motion`` ``(B, N, 4)``, the gap and the pose's
        way field (:func:`models.features.gap_of`, :func:`~models.features.way_channels`).
        """
        if not self.posed:
            return np.stack([s.force for s in scenes])
        if not self.motion:
            return np.stack([s.pose.gap for s in scenes])
        missing = [k for k, s in enumerate(scenes) if s.pose.way is None]
        if missing:
            raise ValueError(
                f"this model reads the way the objects move (option motion), and scene "
                f"{missing[0]}'s pose gives only its gap field"
            )
        return np.stack([np.concatenate([s.pose.gap[:, None], s.pose.way], 1) for s in scenes])

    @property
    def out_channels(self) -> int:
        """The network's outputs per vertex: the displacement, and for a pose the contact
        pressure and its part along the press direction (the reaction's density).
        """
        if self.config.get("held_answer") == "force":
            return 8  # and the forces on the held skin
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

    def forget_scenes(self) -> None:
        """Forget what was kept of the poses answered (priors ``held`` and ``closure``, and the
        linear FEM given a pose): their closures and their held sets' factors
        (:meth:`fem.holding.HeldSkin.forget_poses`); what serves every scene of the body (the
        skin's compliance) stays.
        """
        for skin in (getattr(self, "held_skin", None), getattr(self, "_held", None)):
            if skin is not None:
                skin.forget_poses()

    def predict(self, scenes, strict: bool | None = None):
        """As :meth:`BasePredictor.predict`; a scene on the mirror twin of the model's part
        (anny's right arm for a model of the left: :func:`stmpl.part.mirror_twin`) is
        answered in the mirror: its loads and thickness on the mirrored mesh, the displacement
        mirrored back (``info["mirrored"]``).
        """
        single = isinstance(scenes, Scene)
        if not single and not hasattr(scenes, "__iter__"):
            return super().predict(scenes, strict)  # refused there, by name
        batch = [scenes] if single else list(scenes)  # (a generator is read once, here)
        twins = [mirror_twin(s.part, self.part) if isinstance(s, Scene) else None for s in batch]
        if not any(t is not None for t in twins):
            return super().predict(scenes if single else batch, strict)
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

    def body_tensors(self, part) -> dict:
        """The per-body arrays the network's inputs need, for ``part`` (one body of the mesh)."""
        raise NotImplementedError

    def _answers(self, scenes) -> list:
        """:meth:`predict_batch` of one network call: per scene a displacement ``(N, 3)`` m, or
        a pose model's dict (:func:`models.features.posed_answer`).
        """
        raise NotImplementedError

    def closure_options(self) -> tuple[float, float, str]:
        """``(friction, rounding_m, rule)``: how this model replays a pose's closure
        (:mod:`fem.closure`), as its record of the held skin says (``meta["holding"]``,
        :func:`models.holding.fit_held`): the training set's friction and rounding, and the
        contact rule it was fitted with (``"all_at_once"`` for a model that records none,
        fitted before :data:`fem.closure.CONTACT_RULES` had another).
        """
        record = self.meta["holding"]
        return (
            float(record["friction"]),
            float(record["rounding_m"]),
            str(record.get("contact_rule", "all_at_once")),
        )

    def restore(self, path, meta: dict) -> None:
        """Take a checkpoint's sidecar ``meta`` (read from ``path``): the record, the tissue of
        the data and the envelope; then :meth:`restored`.
        """
        self.meta = {k: v for k, v in meta.items() if k not in ("config", "kind", "envelope")}
        self.tissue = meta.get("dataset", {}).get("tissue", "paper")
        self.friction = meta.get("holding", {}).get("friction")
        self.restored()
        if "envelope" in meta:
            try:
                self.envelope = Envelope.from_dict(meta["envelope"])
            except ValueError as e:
                raise ValueError(f"checkpoint {path}: {e}") from e


def checkpoint_part(path, arrays: dict, meta: dict) -> BodyPart:
    """The body part a checkpoint carries: its ``part.*`` arrays (numpy) and sidecar ``meta``."""
    part = {k[5:]: v for k, v in arrays.items() if k.startswith("part.")}
    return BodyPart.from_arrays(meta["part"], part, meta.get("part_source"))
