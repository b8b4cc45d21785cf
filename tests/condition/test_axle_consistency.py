"""A change of the support is one change under every axle (issue 33).

Both axles of a run pass the same support under the same rails at the same speed. On the real line a false
step read −0.28 ± 0.04 on axle 1 and −0.05 ± 0.06 on axle 4, and the axles' Stouffer sum (−5.3) listed it.
:func:`app.analysis.condition.change.combine_wheels` divides the combined score by the axles' disagreement
beyond their 1-σ (:func:`~app.analysis.condition.change.axle_consistency`, the Birge ratio), in the places'
step test and in the store's step flags alike; a change both axles read keeps its score.
"""

from __future__ import annotations

import numpy as np
import pytest

from app.analysis.condition import RollingHistory, assess_run
from app.analysis.condition.change import axle_consistency, axle_labels, combine_wheels
from app.analysis.condition.run_places import find_places
from app.analysis.condition.segments import SegmentStats
from tests.condition.places_support import PARAMS, SEG, box, runs, track

CLS = np.full(SEG.size, "b91", dtype=object)


def test_axle_labels_are_the_wheel_names_less_their_side():
    assert axle_labels(["11", "12", "41", "42"]).tolist() == ["1", "1", "4", "4"]
    assert axle_labels(["Z11", "Z42"]).tolist() == ["1", "4"]
    assert axle_labels(["left", "7"]).tolist() == ["left", "7"]


def test_the_birge_ratio_of_two_and_of_three_axles():
    # two axles: S² = (c₁ − c₂)² / (s₁² + s₂²); the wheels of an axle averaged
    change = np.array([[-0.28, -0.20, 0.1], [-0.28, -0.20, 0.1], [-0.05, -0.19, np.nan], [-0.05, -0.21, np.nan]])
    sd = np.array([[0.04, 0.05, 0.05]] * 2 + [[0.06, 0.05, 0.05]] * 2)
    s = axle_consistency(change, sd, np.array(["1", "1", "4", "4"], dtype=object))
    assert s[0] == pytest.approx(0.23 / np.hypot(0.04, 0.06))
    assert s[1] == 1.0  # within their errors: unchanged
    assert s[2] == 1.0  # one axle only: nothing to compare
    # three axles about their weighted mean, χ² over 2 degrees of freedom
    c3 = np.array([[0.0], [0.3], [0.0]])
    s3 = axle_consistency(c3, np.full((3, 1), 0.05), np.array(["1", "2", "3"], dtype=object))
    chi2 = ((c3[:, 0] - 0.1) ** 2).sum() / 0.05**2
    assert s3[0] == pytest.approx(np.sqrt(chi2 / 2.0))
    with pytest.raises(ValueError, match="axles"):
        axle_consistency(change, sd, np.array(["1", "4"], dtype=object))
    with pytest.raises(ValueError, match="change, sd"):
        combine_wheels(np.zeros((4, 3)), 2.0, change=change)


def test_combine_wheels_divides_by_the_axles_disagreement():
    z = np.array([[-6.6, -4.0], [-6.6, -4.0], [-0.8, -3.8], [-0.8, -3.8]])
    change = np.array([[-0.277, -0.2], [-0.277, -0.2], [-0.05, -0.19], [-0.05, -0.19]])
    sd = np.abs(change / z)
    series = np.array([0, 0, 2, 2])
    plain, _ = combine_wheels(z, 2.0, series)
    scaled, agree = combine_wheels(z, 2.0, series, change=change, sd=sd)
    assert plain[0] < -4.5 < scaled[0]  # the one-axle change no longer reaches the step score
    assert scaled[1] == pytest.approx(plain[1])  # both axles' change as it was
    assert agree[:, 1].all() and not agree[2:, 0].any()


def _wheels(seg: np.ndarray, per_wheel: dict[str, np.ndarray]) -> dict:
    return {10.0: {w: SegmentStats(seg, np.full(seg.size, 40), np.exp(g), np.exp(g), np.full(seg.size, 30.0), g,
                                   np.full(seg.size, np.nan)) for w, g in per_wheel.items()}}


def test_the_store_flags_a_change_of_both_axles_and_not_one_axles_alone():
    """assess_run: two axles (the two-rail estimate: both wheels of an axle one index) over 100 segments; in the
    newest run segments 20–21 drop by 0.3 under both axles (a support change) and segments 60–61 by 0.3 under
    axle 1 alone. The first is flagged as before, the second no longer."""
    rng = np.random.default_rng(5)
    seg = np.arange(100, dtype=np.int64)
    line = rng.normal(0.0, 0.1, seg.size)

    def run(extra1: np.ndarray, extra4: np.ndarray) -> dict:
        a1 = line + extra1 + rng.normal(0.0, 0.03, seg.size)
        a4 = line + extra4 + rng.normal(0.0, 0.03, seg.size)
        return _wheels(seg, {"11": a1, "12": a1, "41": a4, "42": a4})

    hist = RollingHistory()
    for day in range(10):
        hist.append(float(day * 14), run(np.zeros(seg.size), np.zeros(seg.size)))
    both = np.where((seg >= 20) & (seg < 22), -0.3, 0.0)
    one = np.where((seg >= 60) & (seg < 62), -0.3, 0.0)
    out = assess_run(run(both + one, both), hist, 10 * 14.0)
    steps = sorted({f.seg for f in out.flags if f.kind == "step" and f.seg_m == 10.0})
    assert {20, 21} <= set(steps), steps
    assert not {60, 61} & set(steps), steps


def test_a_run_place_read_by_one_axle_alone_is_not_listed():
    """find_places with the wheels' axles: a −0.25 step over 20 m under both axles is a place; the same step
    under axle 1 alone (axle 4 unchanged) is not."""
    rng = np.random.default_rng(21)
    n = 10
    base = track(np.random.default_rng(22))
    both, alone = box(10_500.0, 10_520.0, -0.25), box(12_000.0, 12_020.0, -0.25)

    def extra(r: int) -> np.ndarray:
        return both + alone if r == n else 0.0 * SEG

    x = runs(rng, base, n + 1, extra)
    x[1], x[3] = x[0], x[2]  # the two-rail estimate: one index per axle
    x[2:, :, n] -= alone  # axle 4 does not read the second step
    days = np.arange(n + 1) * 15.0
    sd = np.full(x.shape, 0.02)
    rp = find_places(SEG, x[:, :, n], x[:, :, :n], days[:n], days[n], CLS, segment_m=10.0, params=PARAMS,
                     index_sd=sd[:, :, n], history_sd=sd[:, :, :n], axles=axle_labels(["11", "12", "41", "42"]))
    assert any(10_500.0 <= c <= 10_520.0 for c in rp.peak_m), rp.peak_m
    assert not any(11_990.0 <= c <= 12_030.0 for c in rp.peak_m), rp.peak_m
    with pytest.raises(ValueError, match="axles"):
        find_places(SEG, x[:, :, n], x[:, :, :n], days[:n], days[n], CLS, segment_m=10.0, params=PARAMS,
                    axles=["1", "4"])
