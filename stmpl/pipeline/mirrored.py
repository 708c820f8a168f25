"""Training on a part that is its own mirror image (anny's belly) with every training press
twice: as solved and in the mirror (training option ``mirror``). A mirrored press is a press
on the same part whose answer is the mirrored answer, so the set's places double for nothing;
a training place whose mirror twin lies in the validation or test split is left out, so that
those splits stay unseen in the mirror too.
"""

from __future__ import annotations

import numpy as np

from stmpl.body.mirror import MIRROR, self_mirror

SCALARS = ("thickness", "force", "gap", "pressure", "push")
"""Per-vertex fields a mirror carries vertex for vertex."""
VECTORS = ("displacement", "linear", "way")
"""Per-vertex ``(N, 3)`` fields a mirror also turns (x negated)."""
RESULTS = ("depth", "reaction", "direction", "centre")
"""A press's ``params`` that are its answer, not its place."""


def twin_of(ds) -> np.ndarray:
    """``(N,)`` each vertex's mirror twin on the dataset's part (:func:`self_mirror`);
    ``ValueError`` for a set of several bodies or a part that is not its own mirror image.
    """
    if len(getattr(ds, "parts", [ds.part])) > 1:
        raise ValueError("mirror: true trains on one body; the data span several")
    twin = self_mirror(ds.part)
    if twin is None:
        raise ValueError(
            f"mirror: true needs a part that is its own mirror image; {ds.part.name} is not "
            "(anny's belly is; a limb's mirror is the other side's limb)"
        )
    return twin


def place(kind: str, params: dict, twin: np.ndarray | None = None) -> tuple:
    """A placement's identity (its kind and what places it), or its mirror twin's with
    ``twin``; ``ValueError`` for a placement not centred on a vertex.
    """
    if not isinstance(params, dict) or "at" not in params:
        raise ValueError(
            f"mirror: true mirrors placements centred on a vertex; {kind} has no centre vertex"
        )
    at = int(params["at"]) if twin is None else int(twin[int(params["at"])])
    rest = tuple(sorted((k, str(v)) for k, v in params.items() if k not in RESULTS + ("at",)))
    return (str(kind), at, rest)


def held_out(ds, a: dict, keep: np.ndarray, twin: np.ndarray) -> np.ndarray:
    """Of the training samples ``keep`` (arrays ``a``), those whose place's mirror twin is no
    validation or test place.
    """
    unseen = set()
    for split in ("val", "test"):
        b = ds.arrays(split)
        unseen |= {place(k, p) for k, p in zip(b["kind"], b["params"])}
    ok = [place(a["kind"][i], a["params"][i], twin) not in unseen for i in keep]
    return keep[np.asarray(ok, dtype=bool)]


def with_mirrored(a: dict, keep: np.ndarray, twin: np.ndarray) -> tuple[dict, np.ndarray]:
    """The samples ``keep`` of arrays ``a``, then each in the mirror (per-vertex fields at
    their twins, vectors with x negated); returns the arrays and the indices of all of them.
    """
    out = {}
    for k in ("body", "total", "placement"):
        if k in a:
            out[k] = np.concatenate([a[k][keep], a[k][keep]])
    for k in SCALARS + VECTORS:
        if k not in a:
            continue
        x = np.asarray(a[k])[keep]
        m = x[:, twin] * (MIRROR if k in VECTORS else 1.0)
        out[k] = np.concatenate([x, m.astype(x.dtype)])
    return out, np.arange(2 * len(keep))
