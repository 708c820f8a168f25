"""How much of a part a predictor models for a scene (the one list, which the command line's
choices come from too).
"""

FIDELITIES = ("full", "auto")
"""All of the part, or what the scene needs (:mod:`stmpl.reach`)."""


def check_fidelity(value) -> str:
    """``value`` if it is one of :data:`FIDELITIES`, else ``ValueError`` naming it."""
    if value not in FIDELITIES:
        raise ValueError(f"fidelity must be one of {list(FIDELITIES)}, got {value!r}")
    return value
