"""The page of a picture (stmpl/viz/page.py): ticks, their labels, wrapped text, colour bars."""

import numpy as np
import pytest
from PIL import Image

from stmpl.viz import page
from stmpl.viz.colours import ramp


@pytest.mark.parametrize(
    "top, values, labels",
    [
        (1.06, [0, 0.2, 0.4, 0.6, 0.8, 1.0], ["0.0", "0.2", "0.4", "0.6", "0.8", "1.0"]),
        (2.0, [0, 0.5, 1, 1.5, 2], ["0.0", "0.5", "1.0", "1.5", "2.0"]),
        (12.0, [0, 2, 4, 6, 8, 10, 12], ["0", "2", "4", "6", "8", "10", "12"]),
        (0.15, [0, 0.025, 0.05, 0.075, 0.1, 0.125, 0.15], None),
    ],
)
def test_ticks_are_round_and_labelled_with_the_decimals_they_need(top, values, labels):
    t = page.ticks(top)
    np.testing.assert_allclose(t, values)
    assert page.tick_labels(t) == (
        labels or ["0.000", "0.025", "0.050", "0.075", "0.100", "0.125", "0.150"]
    )
    with pytest.raises(ValueError, match="positive number"):
        page.ticks(0.0)


def test_text_is_wrapped_to_a_width():
    text = "a contact pressure of 0.19 kPa, reaching 2.10 mm into the skin at rest\nshort"
    wrapped = page.wrap(text, 15, 200)
    lines = wrapped.splitlines()
    assert len(lines) > 2 and lines[-1] == "short"
    assert all(page.text_width(line, 15) <= 200 for line in lines)
    assert " ".join(wrapped.split()) == " ".join(text.split())


def test_a_colour_bar_runs_its_ramp_upward_within_its_reach():
    img = Image.new("RGB", (200, 220), "white")
    right = page.colour_bar(img, (10, 10, 30, 210), "PuBu", 2.0, "pressure (kPa)", 15)
    assert right == 30 + page.bar_space(2.0, "pressure (kPa)", 15)
    px = np.asarray(img) / 255
    np.testing.assert_allclose(px[12, 20], ramp("PuBu", 1.0), atol=0.02)
    np.testing.assert_allclose(px[208, 20], ramp("PuBu", 0.0), atol=0.02)
    assert (px[:, right:] == 1).all()  # nothing beyond its reach
    assert (px[:, 31:right] < 1).any()  # its ticks and label


def test_text_needs_no_matplotlib_to_have_a_font(monkeypatch):
    """Where matplotlib's fonts are not installed, Pillow's own scalable font takes their place
    at the size asked for.
    """
    import importlib.util

    page.font.cache_clear()
    monkeypatch.setattr(importlib.util, "find_spec", lambda name: None)
    try:
        own = page.font(30)
        assert "DejaVu" not in (own.getname()[0] or "")
        assert own.size == 30 and page.text_width("displacement", 30) > 100
    finally:
        page.font.cache_clear()
