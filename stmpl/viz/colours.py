"""Colour ramps for values on the skin, without a plotting library: ColorBrewer's sequential
schemes (Cynthia A. Brewer, colorbrewer2.org, Apache License 2.0), nine classes each, blended
linearly between them as matplotlib's colour maps of the same names are.
"""

from __future__ import annotations

import numpy as np

RAMPS = {
    "YlOrRd": "ffffcc ffeda0 fed976 feb24c fd8d3c fc4e2a e31a1c bd0026 800026",
    "PuBu": "fff7fb ece7f2 d0d1e6 a6bddb 74a9cf 3690c0 0570b0 045a8d 023858",
}
"""Each ramp's nine colours, light to dark (hex RGB): yellow-orange-red for displacement,
purple-blue for contact pressure."""


def ramp(name: str, t: np.ndarray) -> np.ndarray:
    """``(..., 3)`` RGB in [0, 1] of ramp ``name`` at ``t`` ``(...)`` in [0, 1] (a value beyond
    takes the ramp's end colour, as a colour bar's last class does).
    """
    if name not in RAMPS:
        raise ValueError(f"unknown colour ramp {name!r}; known: {', '.join(RAMPS)}")
    t = np.asarray(t, float)
    if not np.isfinite(t).all():
        raise ValueError("colour ramp values must be finite")
    stops = np.array([[int(h[i : i + 2], 16) for i in (0, 2, 4)] for h in RAMPS[name].split()])
    at = np.linspace(0.0, 1.0, len(stops))
    t = np.clip(t, 0.0, 1.0)
    return np.stack([np.interp(t, at, stops[:, j] / 255.0) for j in range(3)], -1)
