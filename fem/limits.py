"""Where a tissue's answers are trusted: the smallest volume ratio anywhere in it and how far
its skin may move inward (a share of the tissue's depth), each bound with its source. The FEM
checks every answer against its tissue's bounds (:meth:`fem.solver.Solver.distrust`) and fails
the ones past them, saying why; a tissue law carries its bounds (``limits``).
"""

from __future__ import annotations

from dataclasses import dataclass

from stmpl.tissue import GEL_TRUSTED_COMPRESSION


@dataclass(frozen=True)
class Limits:
    """Where a tissue's answers are trusted: the smallest volume ratio ``min_det_F`` anywhere in
    it and the largest ``max_compression`` (how far the skin moves inward as a share of the
    tissue's depth under it). ``compression_source`` and ``volume_source`` say where each
    bound comes from.
    """

    min_det_F: float
    max_compression: float
    compression_source: str = ""
    volume_source: str = ""

    def __post_init__(self) -> None:
        if not (0.0 <= self.min_det_F < 1.0 and 0.0 < self.max_compression <= 1.0):
            raise ValueError(
                f"limits need min_det_F in [0, 1) and max_compression in (0, 1], got "
                f"{self.min_det_F!r} and {self.max_compression!r}"
            )

    def reason(self, detF: float, compression: float) -> str:
        """Why a state of smallest volume ratio ``detF`` and skin ``compression`` (a share of
        the tissue's depth) lies past these bounds, or ``""``.
        """
        if detF < self.min_det_F:
            return (
                f"not trusted: the tissue keeps {detF:.2f} of its volume at worst "
                f"(trusted down to {self.min_det_F:g}{_why(self.volume_source)})"
            )
        if compression > self.max_compression:
            return (
                f"not trusted: the skin moves inward {compression:.2f} x the tissue's depth "
                f"(trusted up to {self.max_compression:g}{_why(self.compression_source)})"
            )
        return ""


def _why(source: str) -> str:
    return f"; {source}" if source else ""


GEL = Limits(
    0.0,
    GEL_TRUSTED_COMPRESSION,
    compression_source="the paper's gel buckles from about a third of its depth: past 0.4, "
    "all but one measured answer were the last before it did",
)
"""The compressible neo-Hookean gel's trust bounds (:data:`stmpl.tissue.GEL_TRUSTED_COMPRESSION`,
measured by ``benchmarks/gel_failure.py``)."""
