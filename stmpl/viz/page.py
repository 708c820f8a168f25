"""The page a rendered picture is laid out on, drawn with Pillow: lines of text and colour bars
with their ticks. Sizes are pixels; a font's size is given in points at the page's ``dpi``.
"""

from __future__ import annotations

import functools
import importlib.util
import math
import pathlib

import numpy as np
from PIL import Image, ImageDraw, ImageFont

from stmpl.viz.colours import ramp


@functools.cache
def font(pixels: int) -> ImageFont.FreeTypeFont:
    """DejaVu Sans at ``pixels`` (the font matplotlib ships, found without importing it);
    Pillow's own scalable font where matplotlib's data is not there.
    """
    spec = importlib.util.find_spec("matplotlib")
    for root in (spec.submodule_search_locations or []) if spec else []:
        path = pathlib.Path(root) / "mpl-data" / "fonts" / "ttf" / "DejaVuSans.ttf"
        if path.is_file():
            return ImageFont.truetype(str(path), pixels)
    return ImageFont.load_default(pixels)


def points(pt: float, dpi: float) -> int:
    """Pixels of a ``pt``-point font at ``dpi``."""
    return max(1, round(pt * dpi / 72.0))


def line_height(pixels: int) -> int:
    """Pixels between the tops of two lines of text at ``pixels``."""
    ascent, descent = font(pixels).getmetrics()
    return int(math.ceil(1.15 * (ascent + descent)))


def text_width(text: str, pixels: int) -> int:
    """Pixels across the widest line of ``text``."""
    f = font(pixels)
    return max(int(math.ceil(f.getlength(line))) for line in text.splitlines() or [""])


def write(draw: ImageDraw.ImageDraw, x: float, top: float, text: str, pixels: int, fill="black"):
    """Lines of ``text`` centred on ``x``, the first line's top at ``top``."""
    lh = line_height(pixels)
    for k, line in enumerate(text.splitlines()):
        draw.text((x, top + k * lh), line, fill=fill, font=font(pixels), anchor="ma")


def ticks(top: float, most: int = 6) -> np.ndarray:
    """Round tick values from 0 to at most ``top`` (> 0): a step of 1, 2, 2.5 or 5 times a power
    of ten, the smallest giving at most ``most`` intervals.
    """
    if not (np.isfinite(top) and top > 0):
        raise ValueError(f"a colour bar's top must be a positive number, got {top}")
    power = 10.0 ** math.floor(math.log10(top / most))
    step = next(m * power for m in (1, 2, 2.5, 5, 10, 20) if top / (m * power) <= most)
    return np.arange(0.0, top * (1 + 1e-9) + 1e-300, step)


def tick_labels(values: np.ndarray) -> list[str]:
    """Labels of equally spaced ``values`` with the decimals their step needs."""
    step = float(values[1] - values[0]) if len(values) > 1 else 1.0
    decimals = max(0, -math.floor(math.log10(step) + 1e-9))
    if round(step * 10**decimals, 6) % 1:  # a step of 2.5 x 10^k needs one more
        decimals += 1
    return [f"{v:.{decimals}f}" for v in values]


def colour_bar(
    page: Image.Image, box: tuple, name: str, top: float, label: str, pixels: int
) -> int:
    """Draw ramp ``name`` from 0 (bottom) to ``top`` in ``box`` ``(x0, y0, x1, y1)``, with ticks
    and their values to its right and ``label`` turned upright beyond them; returns the x the
    label ends at.
    """
    x0, y0, x1, y1 = (int(round(v)) for v in box)
    rows = np.linspace(1.0, 0.0, y1 - y0)
    strip = np.round(ramp(name, rows) * 255).astype(np.uint8)
    page.paste(Image.fromarray(np.repeat(strip[:, None], x1 - x0, axis=1)), (x0, y0))
    draw = ImageDraw.Draw(page)
    draw.rectangle((x0, y0, x1, y1), outline="black")
    values = ticks(top)
    labels = tick_labels(values)
    f = font(pixels)
    for v, text in zip(values, labels):
        y = y1 - (y1 - y0) * v / top
        draw.line((x1, y, x1 + 4, y), fill="black")
        draw.text((x1 + 7, y), text, fill="black", font=f, anchor="lm")
    right = x1 + 7 + max(text_width(t, pixels) for t in labels) + 6
    w, h = text_width(label, pixels), line_height(pixels)
    turned = Image.new("RGB", (w + 2, h), "white")
    ImageDraw.Draw(turned).text((1, 0), label, fill="black", font=f)
    turned = turned.rotate(90, expand=True)
    page.paste(turned, (right, int(round((y0 + y1 - turned.height) / 2))))
    return right + turned.width


def wrap(text: str, pixels: int, width: float) -> str:
    """``text`` with each of its lines broken at spaces into lines at most ``width`` pixels
    across at ``pixels`` (a single word wider than that keeps a line of its own).
    """
    f, out = font(pixels), []
    for line in text.splitlines():
        current = ""
        for word in line.split(" "):
            trial = f"{current} {word}" if current else word
            if current and f.getlength(trial) > width:
                out.append(current)
                current = word
            else:
                current = trial
        out.append(current)
    return "\n".join(out)


def bar_space(top: float, label: str, pixels: int) -> int:
    """Pixels right of a colour bar of values 0 to ``top`` that its ticks, their values and its
    upright ``label`` take (as :func:`colour_bar` draws them).
    """
    widest = max(text_width(t, pixels) for t in tick_labels(ticks(top)))
    return 7 + widest + 6 + line_height(pixels)
