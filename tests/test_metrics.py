import numpy as np
import pytest

from stmpl import metrics
from stmpl.body.primitives import tube
from stmpl.metrics import pooled, summarise


def test_sample_metrics_by_hand():
    true = np.zeros((4, 3))
    true[0] = [1e-3, 0, 0]  # 1 mm
    true[1] = [0, 2e-3, 0]  # 2 mm
    true[2] = [0, 0, 0.5e-6]  # 0.0005 mm: below the 0.001 mm threshold, ignored
    pred = true.copy()
    pred[0] += [0, 0, 0.3e-3]  # 0.3 mm error
    pred[1] += [0.05e-3, 0, 0]  # 0.05 mm error
    pred[3] += [9e-3, 0, 0]  # an inactive vertex: ignored
    m = metrics.sample_metrics(true, pred)
    assert m["active"] == 2 and m["max_disp"] == pytest.approx(2.0)
    assert m["mee"] == pytest.approx(0.175)
    assert m["mae_x"] == pytest.approx(0.025) and m["mae_z"] == pytest.approx(0.15)
    assert m["rel_mee"] == pytest.approx(100 * 0.175 / 2.0)
    assert m["max_err"] == pytest.approx(0.3)
    assert m["ee<=0.1"] == 50.0 and m["ee<=0.5"] == 100.0
    # relative to the 2 mm peak: 0.05 mm lies within 5 % (0.1 mm), not within 2 % (0.04 mm)
    assert m["ee<=1%peak"] == m["ee<=2%peak"] == 0.0 and m["ee<=5%peak"] == 50.0
    # the peak counts wherever it is: the inactive vertex's 9 mm against the true 2 mm
    assert m["peak_err"] == pytest.approx(100 * (9.0 / 2.0 - 1))
    pred[3] = 0.0
    assert metrics.sample_metrics(true, pred)["peak_err"] == pytest.approx(
        100 * (np.linalg.norm([0.05, 2.0]) / 2.0 - 1)
    )
    with pytest.raises(ValueError, match="shape|both"):
        metrics.sample_metrics(true, pred[:3])
    with pytest.raises(ValueError, match="finite"):
        metrics.sample_metrics(true, pred * np.nan)


def test_summary_and_tables():
    rows = [{"active": 3, "mee": 1.0, "x": 2.0}, {"active": 3, "mee": 3.0, "x": np.nan}]
    s = metrics.summarise(rows)
    assert s["mee"] == (2.0, 1.0) and s["x"] == (2.0, 0.0) and s["samples"] == 2
    true = np.random.default_rng(0).normal(0, 1e-3, (50, 3))
    s = metrics.summarise([metrics.sample_metrics(true, true + 1e-5)] * 3)
    md = metrics.table({"a": s})
    assert md.startswith("| predictor") and "| a | 3 |" in md
    csv = metrics.table({"a": s}, "csv").splitlines()
    assert csv[0].startswith("predictor,samples,mae_x_mean") and csv[1].startswith("a,3,")
    assert "reaction" not in md  # no row answers a reaction
    assert "seam" not in md  # nor a UV seam's measures (a part without a seam)
    seamed = {**s, "seam_mee": (0.05, 0.01), "seam_gap": (np.nan, np.nan)}
    md = metrics.table({"a": seamed})
    assert "seam MEE" in md and "seam gap" not in md
    posed = {**s, "reaction_err": (-3.25, 1.5)}
    md = metrics.table({"pose model": posed, "a": s}).splitlines()
    head = [c.strip() for c in md[0].split("|")]
    at = head.index("reaction err %")
    assert head[at - 1] == "peak err %"
    assert md[2].split("|")[at].strip() == "-3.2 ± 1.5" and md[3].split("|")[at].strip() == "–"
    csv = metrics.table({"pose model": posed}, "csv").splitlines()
    assert "reaction_err_mean" in csv[0] and ",-3.25,1.5," in csv[1]


def test_seam_gap():
    part = tube(n_around=8, n_along=3)
    corners = np.zeros((len(part.uv), 3))
    assert metrics.seam_gap(part, corners) == 0.0
    g = part.seam_groups[0]
    corners[g[1]] = [0.0, 0.0, 2e-3]  # one copy of one seam vertex 2 mm off
    assert metrics.seam_gap(part, corners) == pytest.approx(2.0 / len(part.seam_groups))


def test_rows_pooled_are_the_row_of_all_their_samples():
    """Pooling two sets' rows gives what one row over both sets' samples gives: means weighted
    by samples, the spread within and between the rows; counts summed, reasons merged.
    """
    rng = np.random.default_rng(0)
    a = [{"rel_mee": x, "peak_err": y} for x, y in rng.normal([1, 2], 0.3, (7, 2))]
    b = [{"rel_mee": x, "peak_err": y} for x, y in rng.normal([3, -1], 0.5, (12, 2))]
    ra, rb = summarise(a), summarise(b)
    ra.update(unsolved=2, unsolved_why={"buckled": 2})
    rb.update(unsolved=3, unsolved_why={"buckled": 1, "stagnated": 2})
    both, whole = pooled([ra, rb]), summarise(a + b)
    assert both["samples"] == 19 and both["unsolved"] == 5
    assert both["unsolved_why"] == {"buckled": 3, "stagnated": 2}
    for k in ("rel_mee", "peak_err"):
        np.testing.assert_allclose(both[k], whole[k], rtol=1e-12)
