"""A predictor that never makes a press wait: where its model would first compute something a
new place needs (a linear prior's columns: :meth:`Predictor.missing`), a stand-in that answers
at once gives the answer, marked as the stand-in's, while the model's work is done in a
background thread; the model answers from then on.

>>> live = Responsive(zoo.read("gnn_arm_bodies", fidelity="auto"), zoo.read("naive_arm_fine"))
>>> d = live.predict(scene)        # at once; d.info["stand_in"] says whose answer it is
>>> live.wait()                    # (optional) until the model has caught up

What a haptic loop or a viewer dragging an object over a body wants: no stall at the first touch
of a place, and never a stand-in's answer passed off as the model's.
"""

from __future__ import annotations

import threading
import warnings

from stmpl.failures import ImpossibleAnswer, OutsideEnvelope
from stmpl.scene import Deformation, Scene


class Responsive:
    """``model`` where it answers at once; elsewhere the first of ``stand_ins`` (one predictor
    or several) that answers at once, while a thread prepares ``model`` for the place. One
    preparation at a time: while it runs every answer is a stand-in's (the model is not asked
    while its caches are being written).

    Where no stand-in answers at once either, the press is refused (``ValueError``), or with
    ``wait`` the model answers itself, however long that takes. ``on_ready()`` is called when a
    preparation ends (to ask for the latest press again), ``on_error(text)`` with what one
    raised; ``errors`` keeps those texts (the stand-ins keep answering there).

    A ``Responsive`` is itself a stand-in for another: its :meth:`missing` is non-zero while
    its model is being prepared. ``name``: what answers say it is (default: the model's).
    """

    def __init__(
        self, model, stand_ins, wait: bool = False, on_ready=None, on_error=None, name=None
    ):
        self.model = model
        self.stand_ins = list(stand_ins) if isinstance(stand_ins, (list, tuple)) else [stand_ins]
        self.name = name or model.name
        self.wait_for_model = wait
        self.on_ready, self.on_error = on_ready, on_error
        self.errors: list[str] = []
        self._busy: threading.Thread | None = None
        self._lock = threading.Lock()
        for p in (model, *self.stand_ins):  # many presses: compiled code loaded now, not by
            load = getattr(p, "load_kernels", None)  # a background solve holding the GIL
            if load is not None:  # (a predictor of the bare interface has none)
                load()

    @property
    def preparing(self) -> bool:
        """Whether the model is being prepared for a place (its answers wait for it)."""
        t = self._busy
        return t is not None and t.is_alive()

    def missing(self, scene: Scene) -> int:
        """What the model would compute before answering ``scene`` (0: it answers at once);
        1 while it is being prepared.
        """
        return 1 if self.preparing else self.model.missing(scene)

    def predict(self, scene: Scene) -> Deformation:
        """The model's answer to ``scene`` if it has everything at hand, else a stand-in's
        (``info["stand_in"] = {"for": model, "by": stand-in}``) while the model is prepared
        for ``scene`` in the background.
        """
        if not isinstance(scene, Scene):
            raise TypeError(f"Responsive.predict takes one Scene, got {type(scene).__name__}")
        if not self.preparing and not self.model.missing(scene):
            return self.model.predict(scene)
        by = next((s for s in self.stand_ins if not s.missing(scene)), None)
        if by is None:
            if not self.wait_for_model:
                names = ", ".join(s.name for s in self.stand_ins) or "none given"
                raise ValueError(f"no stand-in ({names}) can answer at once either")
            self.wait()  # a preparation under way ends first: its caches are not read half-made
            return self.model.predict(scene)
        self._prepare(scene)
        d = by.predict(scene)
        d.info["stand_in"] = {"for": self.name, "by": by.name}
        return d

    def wait(self, timeout: float | None = None) -> bool:
        """Block until the running preparation (if any) ends; whether it has."""
        t = self._busy
        if t is not None:
            t.join(timeout)
        return not self.preparing

    def _prepare(self, scene: Scene) -> None:
        with self._lock:
            if self.preparing:
                return

            def run() -> None:
                try:
                    with warnings.catch_warnings():  # the answer is not kept: only its work
                        warnings.simplefilter("ignore", OutsideEnvelope)
                        warnings.simplefilter("ignore", ImpossibleAnswer)
                        self.model.predict(scene)
                except Exception as e:  # kept and said: the stand-ins answer there meanwhile
                    text = f"{self.name} could not prepare a place: {e}"
                    self.errors.append(text)
                    if self.on_error is not None:
                        self.on_error(text)
                finally:
                    self._busy = None  # ready: a press from now on (on_ready's too) uses it
                    if self.on_ready is not None:
                        self.on_ready()

            self._busy = threading.Thread(target=run, name="stmpl-prepare", daemon=True)
            self._busy.start()
