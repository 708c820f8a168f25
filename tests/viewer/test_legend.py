"""The page's words: the colour scale in round millimetres and the verdict in its colour."""

import pytest

from stmpl.viewer.legend import colour_bar, scale_mm, verdict_html


@pytest.mark.parametrize(
    "deepest, top",
    [(0.0, 0.1), (0.13, 0.2), (0.2, 0.2), (0.43, 0.5), (0.51, 1.0), (3.02, 5.0), (7.0, 10.0)],
)
def test_the_scale_tops_at_the_next_round_number(deepest, top):
    assert scale_mm(deepest) == pytest.approx(top)


def test_a_bad_depth_is_refused():
    with pytest.raises(ValueError, match="finite and >= 0"):
        scale_mm(float("nan"))


def test_the_verdict_is_shown_in_its_colour():
    html = verdict_html("outside", "a < b")
    assert 'data-kind="outside"' in html and "a &lt; b" in html and "OUTSIDE" in html


def test_the_colour_bar_reads_in_millimetres():
    bar = colour_bar(0.5)
    assert (
        "displacement, mm" in bar
        and ">0.25<" in bar
        and ">0.5<" in bar
        and "linear-gradient" in bar
    )
