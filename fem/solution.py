"""The outcome of one FEM solve: the displacement when it converged to a physical state, else
the reason it did not (never a displacement), with the solver's diagnostics.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from fem.mesh import ShellMesh


@dataclass(frozen=True, eq=False)
class Solution:
    """One solve's outcome. ``displacement`` is ``(M, 3)`` in metres at the mesh nodes when
    ``ok``, else ``None``; ``state`` is the solver's full unknown (edge nodes too, for P2), the
    start of a warm-started solve.

    ``reason`` says why a solve failed (``""`` when ok). Diagnostics: Newton ``iterations``,
    relative ``residual``, ``min_det_F`` of the last accepted state, wall ``time`` in s,
    ``total_force`` (sum of per-vertex force magnitudes, N) and ``substeps`` used.
    """

    ok: bool
    reason: str
    displacement: np.ndarray | None
    iterations: int
    residual: float
    min_det_F: float
    time: float
    total_force: float
    substeps: int = 0
    max_displacement: float = float("nan")
    max_compression: float = float("nan")
    state: np.ndarray | None = None
    info: dict = field(default_factory=dict)

    @classmethod
    def failed(
        cls,
        reason: str,
        total_force: float,
        iterations: int = 0,
        residual: float = float("nan"),
        time: float = 0.0,
        substeps: int = 0,
    ) -> "Solution":
        """A failed solve: no displacement, ``reason`` says why."""
        nan = float("nan")
        return cls(False, reason, None, iterations, residual, nan, time, total_force, substeps)

    def diagnostics(self) -> dict:
        """JSON-ready scalars."""
        return {
            "ok": self.ok,
            "reason": self.reason,
            "iterations": self.iterations,
            "residual": self.residual,
            "min_det_F": self.min_det_F,
            "time": self.time,
            "total_force": self.total_force,
            "substeps": self.substeps,
            "max_displacement": self.max_displacement,
            "max_compression": self.max_compression,
        }

    def part_displacement(self, mesh: ShellMesh) -> np.ndarray:
        """``(N, 3)`` displacement of the body part's vertices, m."""
        if not self.ok:
            raise RuntimeError(f"the solve failed ({self.reason}); there is no displacement")
        return self.displacement[mesh.part_nodes]
