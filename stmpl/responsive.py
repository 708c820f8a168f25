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
    """``model`` where it answers at once, ``stand_in`` (which must) elsewhere, while a thread
    prepares ``model`` for the place. One preparation at a time: while it runs every answer is
    the stand-in's (the model is not asked while its caches are being written).

    ``errors`` collects what a preparation raised (the stand-in keeps answering there).
    """

    def __init__(self, model, stand_in):
        self.model, self.stand_in = model, stand_in
        self.name = model.name
        self.errors: list[str] = []
        self._busy: threading.Thread | None = None
        self._lock = threading.Lock()

    @property
    def preparing(self) -> bool:
        """Whether the model is being prepared for a place (its answers wait for it)."""
        t = self._busy
        return t is not None and t.is_alive()

    def predict(self, scene: Scene) -> Deformation:
        """The model's answer to ``scene`` if it has everything at hand, else the stand-in's
        (``info["stand_in"] = {"for": model, "by": stand-in}``) while the model is prepared
        for ``scene`` in the background.
        """
        if not isinstance(scene, Scene):
            raise TypeError(f"Responsive.predict takes one Scene, got {type(scene).__name__}")
        if not self.preparing and not self.model.missing(scene):
            return self.model.predict(scene)
        if self.stand_in.missing(scene):
            raise ValueError(f"the stand-in {self.stand_in.name} cannot answer at once either")
        self._prepare(scene)
        d = self.stand_in.predict(scene)
        d.info["stand_in"] = {"for": self.model.name, "by": self.stand_in.name}
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
                except Exception as e:  # kept and said: the stand-in answers there meanwhile
                    self.errors.append(f"{self.model.name} could not prepare a place: {e}")

            self._busy = threading.Thread(target=run, name="stmpl-prepare", daemon=True)
            self._busy.start()
