"""What an answer is worth, in words: past where the gel buckles, outside the data behind it (with
the reason), or inside it; and the facts a saved mesh carries about the answer it shows.
"""

from __future__ import annotations

from stmpl.tissue import GEL_TRUSTED_COMPRESSION


def impossible(info: dict) -> list[str]:
    """Why a :class:`~stmpl.scene.Deformation`'s ``info`` says its answer cannot be true, each
    reason one clause (empty for a possible answer); an answer saved before the reasons were
    kept says its compression.
    """
    if info.get("physical", True):
        return []
    if info.get("impossible"):
        return list(info["impossible"])
    c = info.get("max_compression", float("nan"))
    return [
        f"the skin moves inward {c:.2f} x the tissue's thickness, past "
        f"{GEL_TRUSTED_COMPRESSION:g}, where the gel buckles and the FEM itself gives no answer"
    ]


def verdict(info: dict) -> tuple[str, str]:
    """``(kind, words)`` of a :class:`~stmpl.scene.Deformation`'s ``info``: ``impossible``
    (past where the gel buckles), ``outside`` (another model standing in for the chosen one,
    or the envelope's first reasons) or ``inside``.
    """
    if not info.get("physical", True):
        return "impossible", "; ".join(impossible(info)) + ": do not use"
    stand_in = info.get("stand_in")  # another model's answer while the chosen one prepares
    if stand_in:
        return "outside", (
            f"a stand-in: {stand_in['by']} answers while {stand_in['for']}'s linear FEM is "
            f"solved for this place (seconds); {stand_in['for']}'s answer follows"
        )
    env = info.get("envelope")
    if env and not env.get("inside", True):
        return "outside", "outside the data it was trained and checked on: " + "; ".join(
            env.get("outside", [])[:2]
        )
    if env is None:
        return "inside", "no envelope: this predictor's answers are the reference"
    return "inside", "inside the data it was trained and checked on"


def facts(deformation, predictor: str) -> dict:
    """What a saved mesh of ``deformation`` says about itself: the predictor, the deepest
    displacement (mm), the verdict and its words (:func:`verdict`), the total force (N; of a
    posed scene's answer, the contact force it answers, and its reaction).
    """
    kind, words = verdict(deformation.info)
    return {
        "predictor": predictor,
        "deepest_mm": round(1e3 * float(deformation.magnitude.max()), 4),
        "force_N": round(float(deformation.applied.sum()), 6),
        **(
            {}
            if deformation.reaction is None
            else {"reaction_N": round(float(deformation.reaction), 6)}
        ),
        "verdict": kind,
        "why": words,
    }
