"""What the page says beside the surface: the colour scale in millimetres and the verdict on
the answer (inside its data, outside with the reason, or past where the gel buckles).
"""

from __future__ import annotations

import html
import math

import numpy as np

ANCHORS = np.array([[205, 160, 135], [240, 150, 95], [215, 60, 40], [120, 0, 20]], dtype=float)
"""The displacement colours from rest to the scale's top: the skin's own tone where it does not
move, through orange and red to dark red where it moves most (RGB)."""


def colours(values_mm: np.ndarray, top_mm: float) -> np.ndarray:
    """``(N, 4)`` uint8 RGBA of displacements ``values_mm`` on a scale from 0 to ``top_mm``."""
    t = np.clip(np.asarray(values_mm, float) / top_mm, 0.0, 1.0) * (len(ANCHORS) - 1)
    k = np.minimum(t.astype(int), len(ANCHORS) - 2)
    f = (t - k)[:, None]
    rgb = (1 - f) * ANCHORS[k] + f * ANCHORS[k + 1]
    return np.column_stack([rgb.round(), np.full(len(rgb), 255.0)]).astype(np.uint8)


VERDICT_COLOURS = {"inside": "#1b7d2f", "outside": "#b35900", "impossible": "#a00000"}


def scale_mm(deepest_mm: float) -> float:
    """The colour scale's top (mm): the next of 1, 2, 5 x 10^k at or above ``deepest_mm``
    (0.1 mm at least), so that the legend reads in round numbers and holds still while an
    answer changes a little.
    """
    if not np.isfinite(deepest_mm) or deepest_mm < 0:
        raise ValueError(f"the deepest displacement must be finite and >= 0, got {deepest_mm!r}")
    x = max(float(deepest_mm), 0.1)
    k = math.floor(math.log10(x))
    for m in (1.0, 2.0, 5.0, 10.0):
        if m * 10**k >= x * (1 - 1e-9):
            return m * 10**k
    return 10.0 ** (k + 1)


def colour_bar(top_mm: float, title: str = "displacement, mm") -> str:
    """HTML of a horizontal colour bar from 0 to ``top_mm`` with its ticks, in mm."""
    cols = ",".join("#%02x%02x%02x" % tuple(int(c) for c in a) for a in ANCHORS)
    ticks = "".join(
        f'<span style="flex:1;text-align:{a}">{top_mm * f:g}</span>'
        for f, a in ((0, "left"), (0.5, "center"), (1, "right"))
    )
    return (
        f'<div style="font-size:0.85em">{html.escape(title)}'
        f'<div id="stmpl-colour-bar" style="height:12px;border-radius:3px;'
        f'background:linear-gradient(to right,{cols})"></div>'
        f'<div style="display:flex">{ticks}</div></div>'
    )


def verdict_html(kind: str, words: str) -> str:
    """The verdict in its colour, for the page."""
    colour = VERDICT_COLOURS[kind]
    title = {"inside": "inside", "outside": "OUTSIDE", "impossible": "NOT AN ANSWER"}[kind]
    return (
        f'<div id="stmpl-verdict" data-kind="{kind}" style="color:{colour};font-weight:600">'
        f'{title}</div><div style="color:{colour};font-size:0.85em">{html.escape(words)}</div>'
    )
