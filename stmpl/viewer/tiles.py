"""A surface cut into tiles so that a changed answer sends the browser only the tiles whose
vertices moved or changed colour, not the whole mesh.
"""

from __future__ import annotations

import numpy as np


def cut(vertices: np.ndarray, faces: np.ndarray, count: int) -> list[np.ndarray]:
    """``count`` groups of face indices of about equal size, contiguous in space: the faces
    sorted along the surface's longest principal direction (a limb's length) and cut into runs.
    """
    if count < 1:
        raise ValueError(f"tile count must be at least 1, got {count}")
    centres = vertices[faces].mean(axis=1)
    c = centres - centres.mean(axis=0)
    axis = np.linalg.svd(c, full_matrices=False)[2][0]
    order = np.argsort(c @ axis, kind="stable")
    return [np.sort(run) for run in np.array_split(order, min(count, len(faces)))]


UNSEEN_MOVE = 5e-5
"""m: a vertex move no one sees. At the viewer's default camera the arm's 0.6 m span fills
about 1000 px, 0.6 mm a pixel: a tile whose vertices all moved less than a twelfth of a pixel
since it was last sent is not sent again."""
UNSEEN_COLOUR = 3
"""A colour change no one sees: at most this many steps (of 255) in every channel."""


class Tiles:
    """The tiles of a mesh ``(V, 3)`` / ``(F, 3)``: each with its own vertices (shared edges
    duplicated) and faces numbered within it. :meth:`changed` says which tiles differ visibly
    from what was last sent (:data:`UNSEEN_MOVE`, :data:`UNSEEN_COLOUR`); the comparison is
    with what was sent, so changes too small to send never add up unseen.
    """

    def __init__(self, vertices: np.ndarray, faces: np.ndarray, count: int = 16):
        self.groups = []
        for run in cut(np.asarray(vertices, float), np.asarray(faces), count):
            used, local = np.unique(faces[run], return_inverse=True)
            self.groups.append((used, local.reshape(-1, 3).astype(np.uint32)))
        self._sent: list = [None] * len(self.groups)

    def __len__(self) -> int:
        return len(self.groups)

    def changed(
        self,
        vertices: np.ndarray,
        colors: np.ndarray,
        tolerance: float = UNSEEN_MOVE,
        colour_step: int = UNSEEN_COLOUR,
    ) -> list:
        """Indices of the tiles to send for ``vertices`` ``(V, 3)`` m and ``colors`` ``(V, 4)``
        uint8: those where a vertex moved more than ``tolerance`` (m) or a colour channel
        changed by more than ``colour_step``; they are taken as sent.
        """
        out = []
        for k, (used, _) in enumerate(self.groups):
            v, c = vertices[used], colors[used]
            last = self._sent[k]
            if (
                last is None
                or np.abs(v - last[0]).max() > tolerance
                or np.abs(c.astype(int) - last[1]).max() > colour_step
            ):
                self._sent[k] = (v.copy(), c.copy())
                out.append(k)
        return out

    def forget(self) -> None:
        """Send every tile next time (a new client, or a new body)."""
        self._sent = [None] * len(self.groups)
