"""Places, tiers, trend and time to limit, identity across runs and section classes (pure numerics),
against synthetic truth."""

from __future__ import annotations

import math

import numpy as np
import pytest

from app.analysis.condition.identity import covering_actions, match_places, tendency
from app.analysis.condition.outlook import linear_trend, time_to_limit
from app.analysis.condition.places import (
    EVIDENCE_ANOMALY,
    EVIDENCE_STEP,
    EVIDENCE_TREND,
    evidence_names,
    merge_places,
)
from app.analysis.condition.section_class import SectionClassLimits, section_classes
from app.analysis.condition.tiers import TierLimits, TierTable, rank_places

# --- places -----------------------------------------------------------------------------------


def _segments_of(change_from_m: float, change_to_m: float, size: float, n: int = 100, segment_m: float = 10.0):
    """Segment means of a box change ``size`` over [from, to) on a flat line (exact coverage)."""
    seg = np.arange(n)
    lo, hi = seg * segment_m, (seg + 1) * segment_m
    cover = np.clip(np.minimum(hi, change_to_m) - np.maximum(lo, change_from_m), 0, None) / segment_m
    return seg, size * cover


@pytest.mark.parametrize("start", [300.0, 303.0, 305.0, 307.5])
def test_a_20m_change_is_one_place_centred_within_a_metre(start):
    seg, v = _segments_of(start, start + 20.0, 0.2)
    p = merge_places(seg, v, np.abs(v) >= 0.05, segment_m=10.0)
    assert len(p) == 1
    assert p.direction[0] == 1
    assert abs(p.centre_m[0] - (start + 10.0)) < 1.0
    assert p.start_m[0] <= start + 5 and p.end_m[0] >= start + 15
    assert p.peak[0] == pytest.approx(0.2)
    assert p.start_m[0] <= p.peak_m[0] <= p.end_m[0]


def test_gap_tolerance_and_direction_split_places():
    seg = np.arange(20)
    v = np.zeros(20)
    v[[2, 3, 5]] = 0.3  # gap of one segment (10 m): one place with gap_m=10
    v[[9, 10]] = 0.3
    v[11] = -0.3  # direction change: new place
    v[[15]] = 0.5
    ex = np.abs(v) > 0.1
    p = merge_places(seg, v, ex, segment_m=10.0, gap_m=10.0)
    assert list(zip(p.start_m, p.end_m, p.direction, strict=True)) == [
        (20.0, 60.0, 1), (90.0, 110.0, 1), (110.0, 120.0, -1), (150.0, 160.0, 1)]
    assert list(p.n_segments) == [3, 2, 1, 1]
    p0 = merge_places(seg, v, ex, segment_m=10.0, gap_m=0.0)
    assert len(p0) == 5  # 20–40 and 50–60 apart now


def test_missing_segments_count_as_gap_and_evidence_wheels_are_unions():
    seg = np.array([0, 1, 2, 5, 6])  # segments 3, 4 without data
    v = np.array([0.0, 0.2, 0.25, 0.3, 0.0])
    ex = v > 0.1
    ev = np.array([0, EVIDENCE_ANOMALY, EVIDENCE_STEP, EVIDENCE_TREND, 0])
    wh = np.array([0, 0b0011, 0b0100, 0b1000, 0])
    p = merge_places(seg, v, ex, segment_m=10.0, gap_m=20.0, evidence=ev, wheels=wh)
    assert len(p) == 1 and p.end_m[0] == 60.0
    assert evidence_names(p.evidence[0]) == ["anomaly", "step", "trend"]
    assert p.wheels[0] == 0b1111
    assert p.peak_m[0] == 55.0
    assert len(merge_places(seg, v, ex, segment_m=10.0, gap_m=10.0)) == 2


def test_no_exceedance_gives_no_place_and_nan_is_no_data():
    seg = np.arange(5)
    assert len(merge_places(seg, np.full(5, np.nan), np.ones(5, bool), segment_m=10.0)) == 0
    assert len(merge_places(seg, np.ones(5), np.zeros(5, bool), segment_m=10.0)) == 0


def test_merge_places_checks_arguments():
    seg = np.arange(3)
    with pytest.raises(ValueError, match="segment_m"):
        merge_places(seg, np.zeros(3), np.zeros(3, bool), segment_m=0.0)
    with pytest.raises(ValueError, match="gap_m"):
        merge_places(seg, np.zeros(3), np.zeros(3, bool), segment_m=10.0, gap_m=-1.0)
    with pytest.raises(ValueError, match="ascending"):
        merge_places(np.array([0, 2, 1]), np.zeros(3), np.zeros(3, bool), segment_m=10.0)
    with pytest.raises(ValueError, match="value"):
        merge_places(seg, np.zeros(4), np.zeros(3, bool), segment_m=10.0)
    with pytest.raises(ValueError, match="integer"):
        merge_places(np.array([0.0, 1.5, 2.0]), np.zeros(3), np.zeros(3, bool), segment_m=10.0)


# --- tiers ------------------------------------------------------------------------------------


def test_tiers_grade_per_class_and_next_limit():
    table = TierTable(TierLimits(0.2, 0.4, 0.7), {"slab": TierLimits(0.1, 0.3, 0.5)})
    sev = np.array([0.05, 0.15, 0.2, 0.45, 0.8, np.nan, 0.15])
    cls = np.array(["", "", "", "", "", "", "slab"], dtype=object)
    tier = table.grade(sev, cls)
    assert list(tier) == [0, 0, 1, 2, 3, 0, 1]
    nxt = table.next_limit(tier, cls)
    assert list(nxt[:4]) == [0.2, 0.2, 0.4, 0.7] and math.isnan(nxt[4]) and nxt[6] == 0.3
    assert table.to_dict()["slab"]["intervention"] == 0.3


def test_tier_limits_must_increase():
    with pytest.raises(ValueError, match="alert, intervention, immediate"):
        TierLimits(0.3, 0.2, 0.5)
    with pytest.raises(ValueError, match="alert, intervention, immediate"):
        TierLimits(0.0, 0.2, 0.5)
    with pytest.raises(TypeError, match="classes"):
        TierTable(TierLimits(0.1, 0.2, 0.3), {"x": (0.1, 0.2, 0.3)})


def test_rank_by_tier_then_time_to_next_then_severity():
    tier = np.array([1, 2, 2, 1, 2, 0])
    days = np.array([30.0, np.nan, 200.0, 10.0, 50.0, 1.0])
    sev = np.array([0.2, 0.5, 0.45, 0.21, 0.41, 0.1])
    assert list(rank_places(tier, days, sev)) == [4, 2, 1, 3, 0, 5]
    tie = rank_places(np.array([1, 1]), np.array([np.nan, np.nan]), np.array([0.2, 0.3]))
    assert list(tie) == [1, 0]


# --- trend and time to limit ---------------------------------------------------------------


def test_trend_interval_covers_truth_and_projection_hits_the_limit():
    rng = np.random.default_rng(1)
    hits, inside = 0, 0
    for _ in range(400):
        days = np.arange(0.0, 168.0, 14.0)
        y = 0.1 + 0.5 * days / 365.25 + rng.normal(0, 0.02, days.size)  # 0.5 per year
        tr = linear_trend(days, y)
        inside += tr.low_per_year <= 0.5 <= tr.high_per_year
        hits += tr.significant
    assert 0.92 <= inside / 400 <= 0.98  # a 95 % interval
    assert hits == 400
    days = np.arange(0.0, 168.0, 14.0)
    tr = linear_trend(days, 0.1 + 0.5 * days / 365.25 + 0.001 * np.sin(days))
    proj = time_to_limit(tr, 0.4)
    # the line is at 0.1 + 0.5 * 154 / 365.25 = 0.311 on the last run: 0.089 / 0.5 years to 0.4
    assert proj.days == pytest.approx(0.089 / 0.5 * 365.25, rel=0.02)
    assert proj.days_early <= proj.days <= proj.days_late


def test_no_projection_without_a_significant_growth():
    rng = np.random.default_rng(2)
    days = np.arange(0.0, 168.0, 14.0)
    flat = linear_trend(days, 0.3 + rng.normal(0, 0.02, days.size))
    assert not flat.significant or abs(flat.rate_per_year) < 0.2
    assert math.isnan(time_to_limit(linear_trend(days, 0.3 - 0.5 * days / 365.25), 0.4).days)  # shrinking
    assert math.isnan(time_to_limit(linear_trend(days[:2], np.array([0.1, 0.2])), 0.4).days)  # 2 points
    tr = linear_trend(days, 0.1 + 0.5 * days / 365.25)
    assert math.isnan(time_to_limit(tr, float("nan")).days)  # top tier
    assert time_to_limit(tr, 0.2).days == 0.0  # already beyond
    assert tendency(tr) == "growing" and tendency(linear_trend(days[:2], np.zeros(2))) == "new"


def test_linear_trend_checks_arguments():
    with pytest.raises(ValueError, match="days, values"):
        linear_trend(np.zeros(3), np.zeros(4))
    with pytest.raises(ValueError, match="confidence"):
        linear_trend(np.arange(3.0), np.zeros(3), confidence=1.0)


# --- identity --------------------------------------------------------------------------------


def test_places_keep_their_identity_across_runs_with_alignment_residuals():
    rng = np.random.default_rng(3)
    centres = np.array([1000.0, 1500.0, 1530.0, 2300.0])
    dirs = np.array([1, -1, 1, -1])
    for _ in range(50):
        jitter = rng.normal(0, 2.0, centres.size)
        grow = rng.choice([0.0, 10.0], centres.size)
        m = match_places(centres - 10 + jitter - grow, centres + 10 + jitter, dirs,
                         centres - 10, centres + 10, dirs, tolerance_m=10.0)
        assert list(m.known) == [0, 1, 2, 3] and m.unconfirmed.size == 0


def test_identity_needs_same_direction_and_overlap():
    m = match_places(np.array([100.0, 400.0, 700.0]), np.array([120.0, 420.0, 720.0]), np.array([1, 1, 1]),
                     np.array([100.0, 440.0, 700.0]), np.array([120.0, 460.0, 720.0]), np.array([-1, 1, 1]),
                     tolerance_m=5.0)
    # 1st: opposite direction → new; 2nd: 20 m apart with 5 m widening → new; 3rd matches
    assert list(m.known) == [-1, -1, 2]
    assert list(m.unconfirmed) == [0, 1]


def test_a_split_place_keeps_its_id_on_the_larger_part():
    m = match_places(np.array([100.0, 160.0]), np.array([150.0, 170.0]), np.array([1, 1]),
                     np.array([100.0]), np.array([170.0]), np.array([1]), tolerance_m=5.0)
    assert list(m.known) == [0, -1]


def test_covering_actions():
    got = covering_actions(100.0, 140.0, np.array([0.0, 120.0, 130.0, 500.0]), np.array([200.0, 200.0, 140.0, 600.0]))
    assert list(got) == [0, 1]
    with pytest.raises(ValueError, match="min_cover"):
        covering_actions(0.0, 1.0, np.zeros(1), np.ones(1), min_cover=0.0)


# --- section classes ---------------------------------------------------------------------------


def test_section_classes_from_level_and_spread():
    limits = SectionClassLimits(0.05, 0.1, 0.2, 0.3)
    rng = np.random.default_rng(4)
    seg = np.arange(100)  # 1 km of 10 m segments, five 200 m sections
    x = np.empty(100)
    x[0:20] = rng.normal(0, 0.02, 20)          # A
    x[20:40] = 0.08 + rng.normal(0, 0.01, 20)  # level 0.08: B
    x[40:60] = rng.normal(0, 0.15, 20)         # spread ~0.15: C (or D by chance of the sample)
    x[60:80] = 0.5                              # E
    x[80:100] = np.nan
    x[80:85] = 0.0                              # 5 of 20: not enough data
    sc = section_classes(seg, x, segment_m=10.0, limits=limits)
    assert list(sc.start_m) == [0.0, 200.0, 400.0, 600.0, 800.0]
    assert list(sc.cls[[0, 1, 3, 4]]) == ["A", "B", "E", ""]
    assert sc.cls[2] in ("C", "D")
    assert sc.rms[3] == pytest.approx(0.5) and sc.spread[3] == pytest.approx(0.0)
    assert sc.length_by_class()["E"] == 200.0 and sc.length_by_class()[""] == 200.0
    with pytest.raises(ValueError, match="section_m"):
        section_classes(seg, x, segment_m=10.0, limits=limits, section_m=205.0)
    with pytest.raises(ValueError, match="a, b, c, d"):
        SectionClassLimits(0.1, 0.1, 0.2, 0.3)


def test_a_section_on_rough_rails_is_classed_by_its_support_not_the_rails_scatter():
    """Issue 33: the rails' response at the sleeper spacing changes from one 10 m segment to the next (each
    rail's short-wave roughness): on the rough line it scattered 0.3 and read "E: very poor" over 1.6 of
    2.9 km of sound support. Given that scatter (the places' :func:`class_scatter` of the run), the section's
    spread is the support's; a support that does vary (a soft 60 m) still does; smooth rails (no scatter
    beyond the healthy one: 0) are classed as before."""
    from app.analysis.condition.run_places import class_scatter

    limits = SectionClassLimits(0.05, 0.10, 0.17, 0.25)
    rng = np.random.default_rng(33)
    seg = np.arange(1000, 1160)  # 1.6 km, eight sections
    support = np.zeros(seg.size)
    support[100:106] = -0.5  # a soft 60 m in the sixth section
    rails = rng.normal(0.0, 0.30, seg.size)
    x = support + rails + rng.normal(0.0, 0.03, seg.size)
    cls = np.full(seg.size, "b91", dtype=object)
    alert = np.full(seg.size, 0.25)
    scatter = class_scatter(x, cls, alert, seg)
    assert np.all(np.abs(scatter - 0.30) < 0.06)
    plain = section_classes(seg, x, segment_m=10.0, limits=limits)
    assert sum(plain.cls == "E") >= 6 and np.all(np.isin(plain.cls, ["D", "E"]))  # what the page showed
    sc = section_classes(seg, x, segment_m=10.0, limits=limits, rail_scatter=scatter)
    assert sc.rail_spread == pytest.approx(scatter[::20], abs=1e-12)
    sound = [k for k in range(8) if k != 5]
    assert sum(c in ("A", "B", "C") for c in sc.cls[sound]) >= 5 and sc.cls[5] in ("D", "E")
    assert sc.rms[5] > max(sc.rms[sound])
    assert np.all(sc.spread <= plain.spread) and np.all(sc.level == plain.level)
    # smooth rails: the scatter is a pass's noise, below the healthy one: 0, the classes as without it
    calm = support + rng.normal(0.0, 0.03, seg.size)
    none = class_scatter(calm, cls, alert, seg)
    assert np.all(none == 0.0)
    same = section_classes(seg, calm, segment_m=10.0, limits=limits, rail_scatter=none)
    assert list(same.cls) == list(section_classes(seg, calm, segment_m=10.0, limits=limits).cls)
    with pytest.raises(ValueError, match="rail_scatter"):
        section_classes(seg, x, segment_m=10.0, limits=limits, rail_scatter=scatter[:5])
    with pytest.raises(ValueError, match="rail_scatter"):
        section_classes(seg, x, segment_m=10.0, limits=limits, rail_scatter=-scatter)
    with pytest.raises(ValueError, match="rail_scatter"):
        section_classes(seg, x, segment_m=10.0, limits=limits, rail_scatter=np.full(seg.size, np.inf))


# --- known discontinuities -----------------------------------------------------------------------


def test_assets_at_labels_places_within_the_buffer():
    from app.analysis.condition.discontinuities import assets_at

    hits = assets_at(np.array([100.0, 500.0, 900.0]), np.array([120.0, 530.0, 910.0]),
                     np.array([125.0, 300.0, 480.0, 505.0, 2000.0]), np.array([125.0, 400.0, 480.0, 600.0, 2000.0]),
                     buffer_m=20.0)
    assert list(hits.of(0)) == [0]  # a weld 5 m after the place
    assert list(hits.of(1)) == [2, 3]  # a point 20 m before (at the buffer), a bridge overlapping
    assert list(hits.of(2)) == []
    assert hits.distance_m[hits.place == 1].tolist() == [20.0, 0.0]
    with pytest.raises(ValueError, match="buffer_m"):
        assets_at(np.zeros(1), np.zeros(1), np.zeros(1), np.zeros(1), buffer_m=-1.0)
    with pytest.raises(ValueError, match="asset_from_m"):
        assets_at(np.zeros(1), np.zeros(1), np.array([2.0]), np.array([1.0]))


def test_section_class_values_are_exact_and_boundaries_belong_to_the_better_class():
    limits = SectionClassLimits(0.05, 0.10, 0.17, 0.25)
    seg = np.arange(-20, 40)  # three 200 m sections, the first at km −0.2 (negative segment numbers)
    x = np.empty(60)
    x[0:20] = 0.03 + np.where(np.arange(20) % 2 == 0, 0.04, -0.04)  # level 0.03, spread 0.04·√(20/19)
    x[20:40] = 0.10                                                 # rms exactly at B's upper limit: B
    x[40:60] = -0.2
    x[[41, 43]] = np.nan                                            # 18 of 20 with data
    sc = section_classes(seg, x, segment_m=10.0, limits=limits)
    assert list(sc.section) == [-1, 0, 1] and list(sc.start_m) == [-200.0, 0.0, 200.0]
    spread0 = 0.04 * np.sqrt(20 / 19)
    assert sc.level[0] == pytest.approx(0.03) and sc.spread[0] == pytest.approx(spread0)
    assert sc.rms[0] == pytest.approx(np.hypot(0.03, spread0))  # 0.051: B
    assert list(sc.cls) == ["B", "B", "D"]
    assert list(sc.n_segments) == [20, 20, 18] and sc.level[2] == pytest.approx(-0.2)  # soft counts as departure
    # 100 m sections (a setting): the first 200 m splits into two sections with the same level and spread
    sc100 = section_classes(seg, x, segment_m=10.0, limits=limits, section_m=100.0)
    assert len(sc100) == 6 and sc100.spread[0] == pytest.approx(0.04 * np.sqrt(10 / 9))
    # a section with too few values has no class (and no level), but is listed
    sparse = np.full(60, np.nan)
    sparse[:9] = 0.0
    one = section_classes(seg, sparse, segment_m=10.0, limits=limits, min_fill=0.5)
    assert list(one.cls) == ["", "", ""] and np.isnan(one.level).all()
    assert section_classes(seg, sparse, segment_m=10.0, limits=limits, min_fill=0.45).cls[0] == "A"
    with pytest.raises(ValueError, match="min_fill"):
        section_classes(seg, x, segment_m=10.0, limits=limits, min_fill=0.0)
    with pytest.raises(TypeError, match="limits"):
        section_classes(seg, x, segment_m=10.0, limits=(0.05, 0.1, 0.17, 0.25))  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="seg, index"):
        section_classes(seg, x[:5], segment_m=10.0, limits=limits)


def test_section_class_lengths_follow_a_line_that_degrades():
    limits = SectionClassLimits(0.05, 0.10, 0.17, 0.25)
    rng = np.random.default_rng(9)
    seg = np.arange(200)  # 2 km, ten sections
    before = rng.normal(0, 0.03, 200)
    after = before.copy()
    after[40:80] += 0.2  # two sections 20 % stiffer a year later
    a = section_classes(seg, before, segment_m=10.0, limits=limits).length_by_class()
    b = section_classes(seg, after, segment_m=10.0, limits=limits).length_by_class()
    assert a["A"] == 2000.0
    assert b["A"] == 1600.0 and b["D"] == 400.0
    assert sum(b.values()) == 2000.0
