"""Force control over any predictor that answers a pose: the objects of a posed scene moved
along their press (a grip: closed along its paths) until the reaction the predictor answers
meets a force. What an application knows may be the force (a grasp of 5 N) while a model
trained on pressed objects takes where they are; this finds where they are.

>>> scene = posed(arm, thickness, tip, objects.press(arm, tip, uv=(0.5, 0.5), depth=0.0))
>>> answer = to_force(model, scene, 5.0)        # the tip pressed until it meets 5 N
>>> answer.reaction, answer.info["force_control"]["moved_mm"]

The search: from the scene's pose, steps of :data:`STEP` (doubling) forward until the
reaction passes the force, or back until it falls below it; then regula falsi (Illinois)
between the last two, until the reaction is within ``rtol`` of the force. A predictor whose
reaction never reaches the force within :data:`REACH` of travel or before its answers turn
impossible (past the tissue's bound), or that jumps across it (a reaction that is not monotone
in the depth), is refused by name (:class:`ForceNotMet`):
no answer at another force is returned as one at this force. The answer returned is the
predictor's own answer to the scene at the depth found (its envelope's verdict, impossible
flags and warnings as for any answer), with ``info["force_control"]``. A predictor with force
control of its own (a method ``to_force(scene, force, rtol, strict)``: the FEM's, which meets
the force within one press instead of a search over whole presses) is handed the request.
"""

from __future__ import annotations

import time
import warnings

import numpy as np

from stmpl.contact.posing import moved
from stmpl.predictor import ImpossibleAnswer, OutsideEnvelope
from stmpl.scene import Scene

STEP = 0.001
"""m: the first step of the search for a bracket (then doubled)."""

REACH = 0.03
"""m: how far the objects may travel from the scene's pose, either way, before the search
gives up (deeper than any tissue the presets carry)."""

TRIES = 40
"""Answers the search may ask for."""


class ForceNotMet(ValueError):
    """The predictor's reaction does not meet the force along the objects' travel."""


def to_force(predictor, scene: Scene, force: float, rtol: float = 0.005, strict=None):
    """The :class:`~stmpl.scene.Deformation` ``predictor`` answers when ``scene``'s objects
    (given by their pose) are moved along their press until its reaction is ``force`` (N)
    within ``rtol``. ``info["force_control"]``: the force asked, the reaction met, how far the
    objects moved from the scene's pose (mm) and how many answers it took. ``strict`` as for
    :meth:`~stmpl.predictor.BasePredictor.predict`, for the answer returned.
    """
    if scene.given != "pose":
        raise ValueError(
            "force control moves objects given by their pose: this scene gives a force"
        )
    if not scene.pose.objects:
        raise ValueError("force control moves the objects, and this pose gives only its gap field")
    if not (np.isfinite(force) and force > 0):
        raise ValueError(f"the force to meet must be above 0 N, got {force!r}")
    if not 0 < rtol < 0.5:
        raise ValueError(f"rtol must lie in (0, 0.5), got {rtol!r}")
    own = getattr(predictor, "to_force", None)
    if own is not None:  # a predictor with force control of its own (the FEM's)
        return own(scene, force, rtol, strict)
    t0 = time.perf_counter()
    seen: dict[float, float] = {}
    at: dict[float, Scene] = {}  # the scenes tried (the answer's is asked again, judged)

    def reaction(d: float) -> float:
        if d not in seen:
            at[d] = moved(scene, d)
            with warnings.catch_warnings():  # the answer returned is judged, not the tries
                warnings.simplefilter("ignore", OutsideEnvelope)
                warnings.simplefilter("ignore", ImpossibleAnswer)
                a = predictor.predict(at[d], strict=False)
            seen[d] = float(a.reaction)
            if seen[d] < force and not a.info.get("physical", True):
                raise ForceNotMet(
                    f"{predictor.name}: the reaction reaches only {seen[d]:.3g} N where the "
                    f"answer is no longer possible ({'; '.join(a.info['impossible'])}): "
                    f"{force:g} N is not met"
                )
            if len(seen) > TRIES:
                raise ForceNotMet(f"{predictor.name}: {force:g} N not met in {TRIES} answers")
        return seen[d]

    lo, hi = _bracket(predictor.name, reaction, force)
    d = _between(predictor.name, reaction, force, rtol, lo, hi)
    if hasattr(predictor, "forget_scenes"):  # its time a new scene's, not a kept try's
        predictor.forget_scenes()
    answer = predictor.predict(at[d], strict=strict)
    answer.info["force_control"] = {
        "force": float(force),
        "reaction": float(answer.reaction),
        "moved_mm": 1e3 * d,
        "answers": len(seen) + 1,
        "seconds": time.perf_counter() - t0,
    }
    return answer


def _bracket(name: str, reaction, force: float) -> tuple[float, float]:
    """Depths ``(lo, hi)`` (m from the pose) with ``reaction(lo) < force <= reaction(hi)``."""
    a, ra = 0.0, reaction(0.0)
    way = 1.0 if ra < force else -1.0
    step = STEP
    while True:
        b = a + way * step
        if abs(b) > REACH:
            if way > 0:
                raise ForceNotMet(
                    f"{name}: the reaction reaches only {ra:.3g} N with the objects moved "
                    f"{1e3 * a:.3g} mm on from their pose: {force:g} N is not met within "
                    f"{1e3 * REACH:g} mm of travel"
                )
            raise ForceNotMet(
                f"{name}: the reaction is still {ra:.3g} N with the objects moved "
                f"{1e3 * -a:.3g} mm back from their pose: it never falls below {force:g} N"
            )
        rb = reaction(b)
        if (rb >= force) if way > 0 else (rb < force):
            return (a, b) if way > 0 else (b, a)
        a, ra, step = b, rb, 2 * step


def _between(name: str, reaction, force: float, rtol: float, lo: float, hi: float) -> float:
    """The depth in ``[lo, hi]`` whose reaction is ``force`` within ``rtol``: regula falsi with
    the Illinois rule (the side that stays has its excess halved).
    """
    flo, fhi = reaction(lo) - force, reaction(hi) - force
    if abs(fhi) <= rtol * force:
        return hi
    side = 0
    while hi - lo > 1e-9:
        d = hi - fhi * (hi - lo) / (fhi - flo)
        if not lo < d < hi:
            d = 0.5 * (lo + hi)
        r = reaction(d) - force
        if abs(r) <= rtol * force:
            return d
        if r < 0:
            lo, flo = d, r
            fhi = fhi / 2 if side < 0 else fhi
            side = -1
        else:
            hi, fhi = d, r
            flo = flo / 2 if side > 0 else flo
            side = 1
    raise ForceNotMet(
        f"{name}: the reaction jumps from {reaction(lo):.3g} to {reaction(hi):.3g} N across "
        f"{force:g} N within 1 nm of depth (at {1e3 * lo:.4g} mm from the pose): not met"
    )
