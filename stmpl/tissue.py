"""Soft-tissue thickness per vertex, in metres.

The paper's heuristic ties thickness to body shape: thin to thick bodies get a constant
5.0 .. 10.0 mm (anny's ``weight`` phenotype 0 .. 1; SMPL's beta_2 -2 .. 2). Beyond the paper, any
smooth per-vertex map is allowed (``ramp``, ``bumps``, ``smooth``). Learned models see thickness
normalised to [0, 1] over :data:`THICKNESS_RANGE`; values outside it are refused, never clipped.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from stmpl.part import BodyPart

THICKNESS_RANGE = (0.0025, 0.0125)
"""Normalisation range of thickness, m (the paper's [2.5, 12.5] mm)."""

GEL_TRUSTED_COMPRESSION = 0.4
"""How far the skin may move inward on the paper's gel, as a share of the tissue's depth, and
still be trusted. Measured on force ramps of the gel's own load model that keep their failed
solves (``benchmarks/gel_failure.py``, ``docs/tissue.md``): ramps buckle after a last answer
at a median 0.31 compression, and of the answers solved past 0.4, all but one were the last
before the gel buckled (19 of 20 on the gel-failure set, 8 of 9 on the honesty set). Creasing
(0.35; Hong, Zhao & Suo 2009, Appl. Phys. Lett. 95:111901) and Biot's surface instability
(0.46) of a compressed neo-Hookean solid bracket it. The FEM fails an answer past it; a
predictor's answer past it is flagged as no answer to trust."""


@dataclass(frozen=True)
class Bound:
    """How far an answer may push the skin inward before it is one the FEM itself would not give:
    ``compression`` of the tissue's whole depth, which is the scene's thickness (skin and fat)
    and ``below`` (m) under it: 0 for the paper's gel, a layered tissue's muscle at its deepest
    (so that the bound never fires on an answer the FEM could give). ``depth`` names that depth
    and ``words`` say what lies past it.
    """

    compression: float = GEL_TRUSTED_COMPRESSION
    below: float = 0.0
    depth: str = "thickness"
    words: str = "where the gel buckles and the FEM itself gives no answer"

    def of(self, inward: np.ndarray, thickness: np.ndarray) -> float:
        """The largest of ``inward`` ``(N,)`` (m, the skin's inward displacement) over the
        whole depth under each vertex, ``thickness`` ``(N,)`` (m) and :attr:`below`.
        """
        return float((inward / (thickness + self.below)).max())

    def reason(self, compression: float) -> str:
        """Why an answer of ``compression`` (:meth:`of`) past the bound cannot be true."""
        return (
            f"the skin moves inward {compression:.2f} x the tissue's {self.depth}, past "
            f"{self.compression:g}, {self.words}"
        )


GEL = Bound()
"""The paper's gel: past :data:`GEL_TRUSTED_COMPRESSION` of its thickness."""


LEVELS = (0.005, 0.00625, 0.0075, 0.00875, 0.010)
"""The paper's five thickness levels, m (thin to thick body)."""


def check(part: BodyPart, thickness) -> np.ndarray:
    """Validate a thickness map: ``(N,)``, finite, inside :data:`THICKNESS_RANGE`."""
    t = np.asarray(thickness, dtype=float)
    if t.shape != (part.n_vertices,):
        raise ValueError(
            f"thickness must have shape ({part.n_vertices},) for part {part.name!r}, got {t.shape}"
        )
    bad = ~np.isfinite(t)
    if bad.any():
        raise ValueError(
            f"thickness is not finite at {bad.sum()} vertices (first: vertex "
            f"{np.argmax(bad)}, value {t[np.argmax(bad)]})"
        )
    lo, hi = THICKNESS_RANGE
    slack = 1e-6  # a map stored in single precision (a dataset's) may lie a rounding past a bound
    out = (t < lo * (1 - slack)) | (t > hi * (1 + slack))
    if out.any():
        i = int(np.argmax(out))
        raise ValueError(
            f"thickness must lie in [{lo * 1e3:g}, {hi * 1e3:g}] mm (the model's "
            f"normalisation range); vertex {i} has {t[i] * 1e3:g} mm "
            f"({out.sum()} vertices outside)"
        )
    return t


def constant(part: BodyPart, thickness: float) -> np.ndarray:
    """The same thickness (m) at every vertex."""
    return check(part, np.full(part.n_vertices, float(thickness)))


def from_weight(part: BodyPart, weight: float) -> np.ndarray:
    """The paper's heuristic through anny's ``weight`` phenotype: 0 -> 5 mm, 1 -> 10 mm."""
    w = float(weight)
    if not np.isfinite(w) or not 0.0 <= w <= 1.0:
        raise ValueError(f"weight phenotype must be in [0, 1], got {weight}")
    return constant(part, 0.005 + 0.005 * w)


def from_beta2(part: BodyPart, beta2: float) -> np.ndarray:
    """The paper's heuristic through SMPL's second shape coefficient: -2 -> 5 mm, 2 -> 10 mm."""
    b = float(beta2)
    if not np.isfinite(b) or not -2.0 <= b <= 2.0:
        raise ValueError(f"beta_2 must be in [-2, 2] (the paper's sweep), got {beta2}")
    return constant(part, 0.0075 + 0.00125 * b)


def ramp(part: BodyPart, start: float, end: float) -> np.ndarray:
    """Thickness varying linearly along a limb's axis, ``start`` (m) proximal to ``end`` distal."""
    s = part.axial
    f = (s - s.min()) / max(s.max() - s.min(), 1e-12)
    return check(part, start + (end - start) * f)


def bumps(
    part: BodyPart,
    base: float,
    amplitude: float,
    length: float = 0.05,
    count: int = 4,
    seed: int = 0,
) -> np.ndarray:
    """``base`` plus ``count`` Gaussian bumps of height up to ``amplitude`` (m) and width
    ``length`` (m) at random vertices: a smooth, non-constant map (seeded).
    """
    rng = np.random.default_rng(seed)
    centres = part.vertices[rng.choice(part.n_vertices, size=count, replace=False)]
    heights = amplitude * rng.uniform(-1.0, 1.0, size=count)
    d2 = ((part.vertices[:, None] - centres[None]) ** 2).sum(-1)
    return check(part, base + (heights * np.exp(-d2 / (2 * length**2))).sum(1))


def smooth(part: BodyPart, values, iterations: int = 10, step: float = 0.5) -> np.ndarray:
    """Laplacian smoothing of any per-vertex map ``(N,)`` (e.g. painted thickness)."""
    v = np.asarray(values, dtype=float).copy()
    if v.shape != (part.n_vertices,) or not np.isfinite(v).all():
        raise ValueError(f"values must be finite with shape ({part.n_vertices},), got {v.shape}")
    e = part.edges
    n = part.n_vertices
    adj = sp.coo_matrix(
        (np.ones(2 * len(e)), (np.r_[e[:, 0], e[:, 1]], np.r_[e[:, 1], e[:, 0]])), shape=(n, n)
    ).tocsr()
    deg = np.asarray(adj.sum(1)).ravel()
    for _ in range(int(iterations)):
        v = v + step * (adj @ v / deg - v)
    return v


def normalise(thickness):
    """Map thickness (m) to [0, 1] over :data:`THICKNESS_RANGE`: NumPy arrays and torch tensors
    keep their type and dtype (the learned models' thickness input); other sequences become
    float arrays.
    """
    lo, hi = THICKNESS_RANGE
    if not hasattr(thickness, "dtype"):
        thickness = np.asarray(thickness, float)
    return (thickness - lo) / (hi - lo)


def denormalise(x) -> np.ndarray:
    """Inverse of :func:`normalise`."""
    lo, hi = THICKNESS_RANGE
    return lo + np.asarray(x, float) * (hi - lo)
