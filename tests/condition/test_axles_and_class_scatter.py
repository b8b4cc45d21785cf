"""Two statistics of a run's places on rough rails (issue 33):

* the two wheels of an axle give one index (the two-rail estimate), so their scores are one witness: the wheels'
  combined score counts it once (:func:`app.analysis.condition.change.combine_wheels`), and the stated error is
  shared by the axles, not by four wheels (:func:`app.analysis.condition.change.series_labels`);
* a level is graded against the scatter its class shows across the run's segments where that exceeds the
  healthy scatter the limits stand for, read from one segment to the next
  (:func:`app.analysis.condition.run_places.class_scatter`): the rails' response at the sleeper spacing where
  the stated 1-σ misses it, not a long extent of the support.
"""

from __future__ import annotations

import numpy as np
import pytest

from app.analysis.condition.change import combine_wheels, detect_changes, series_labels
from app.analysis.condition.places import EVIDENCE_ANOMALY
from app.analysis.condition.run_places import HEALTHY_ALERT_Z, class_scatter, find_places
from tests.condition.places_support import PARAMS, SEG, box, runs, track

CLS = np.full(SEG.size, "b91", dtype=object)
ALERT = PARAMS.levels.limits_for("b91").alert


def test_an_axles_two_wheels_are_one_witness():
    axles = series_labels([np.array([0.3, 0.1]), np.array([0.3, 0.1 + 1e-16]), np.array([0.2, 0.0]),
                           np.array([0.2, 0.0])])
    assert axles.tolist() == [0, 0, 2, 2]
    # two axles, each wheel of an axle with its axle's score: (z1 + z4) / √2, not z1 + z4
    combined, agree = combine_wheels(np.array([[4.0], [4.0], [2.0], [2.0]]), 2.0, axles)
    assert combined[0] == pytest.approx(6.0 / np.sqrt(2.0))
    assert agree[:, 0].tolist() == [True, True, True, True]
    # without series, or four wheels of their own: Stouffer as before
    assert combine_wheels(np.array([[4.0], [4.0], [2.0], [2.0]]), 2.0)[0][0] == pytest.approx(6.0)
    assert combine_wheels(np.array([[4.0], [3.0], [2.0], [1.0]]), 2.0, np.arange(4))[0][0] == pytest.approx(5.0)
    # a series counts as often as its wheels are scored
    z = np.array([[5.0, np.nan], [5.0, 1.0], [0.0, 1.0], [0.0, np.nan]])
    c, _ = combine_wheels(z, 2.0, axles)
    assert c[0] == pytest.approx(5.0 / np.sqrt(2.0)) and c[1] == pytest.approx(2.0 / np.sqrt(2.0))
    # one axle's outlier of z 6 against a quiet axle no longer reaches the step score (4.5); counted twice it did
    assert abs(combine_wheels(np.array([[6.0], [6.0], [0.2], [0.2]]), 2.0, axles)[0][0]) < 4.5
    with pytest.raises(ValueError, match="series"):
        combine_wheels(z, 2.0, axles[:3])


def test_series_labels_name_the_wheels_with_an_index_of_their_own():
    a = np.array([0.1, np.nan, -0.2])
    b = np.array([0.3, 0.1, np.nan])
    assert series_labels([a, a + 1e-16, b, b.copy()]).tolist() == [0, 0, 2, 2]
    assert series_labels([a, b]).tolist() == [0, 1]
    assert series_labels([a]).tolist() == [0] and series_labels([]).tolist() == []
    assert series_labels([a, a[:2]]).tolist() == [0, 1]
    assert series_labels([b, a, b]).tolist() == [0, 1, 0]


def test_a_runs_axle_scores_combine_as_two_witnesses():
    # the run's places combine their wheels as the two axles they are: the combined step score is the axles'
    # scores over √2, each axle tested with the stated error shared by two, and divided by the axles'
    # disagreement beyond their 1-σ where there is any (two axles: S² = (c₁ − c₄)² / (s₁² + s₄²))
    rng = np.random.default_rng(11)
    n = 10
    x = runs(rng, track(np.random.default_rng(12)), n + 1,
             lambda r: box(11_000.0, 11_020.0, -0.2) if r == n else 0.0 * SEG)
    x[1], x[3] = x[0], x[2]
    sd = np.full(x.shape, 0.03)
    days = np.arange(n + 1) * 15.0
    rp = find_places(SEG, x[:, :, n], x[:, :, :n], days[:n], days[n], CLS, segment_m=10.0, params=PARAMS,
                     index_sd=sd[:, :, n], history_sd=sd[:, :, :n])
    ch = [detect_changes(x[w, :, :n], np.ones((SEG.size, n)), days[:n], x[w, :, n], np.ones(SEG.size), days[n], SEG,
                         segment_m=10.0, params=PARAMS.change_params(), trend=True, sd_value=sd[w, :, n],
                         sd_history=sd[w, :, :n], stated_wheels=2) for w in (0, 2)]
    z = [c.change_z for c in ch]
    birge = np.sqrt(np.fmax((ch[0].change - ch[1].change) ** 2 / (ch[0].change_sd**2 + ch[1].change_sd**2), 1.0))
    assert 0 < int((birge > 1.0).sum()) < SEG.size  # both kinds of segment are tested
    np.testing.assert_allclose(rp.seg_change_z, (z[0] + z[1]) / np.sqrt(2.0) / birge, rtol=1e-9, equal_nan=True)
    k = int(np.searchsorted(SEG, 1100))
    assert rp.seg_change_z[k] < -4.5  # the planted step is found
    # one wheel measured (the others without an index): one witness, its stated error its own
    one = np.full(x.shape, np.nan)
    one[0] = x[0]
    rp1 = find_places(SEG, one[:, :, n], one[:, :, :n], days[:n], days[n], CLS, segment_m=10.0, params=PARAMS,
                      index_sd=sd[:, :, n], history_sd=sd[:, :, :n])
    z1 = detect_changes(x[0, :, :n], np.ones((SEG.size, n)), days[:n], x[0, :, n], np.ones(SEG.size), days[n], SEG,
                        segment_m=10.0, params=PARAMS.change_params(), trend=True, sd_value=sd[0, :, n],
                        sd_history=sd[0, :, :n], stated_wheels=1).change_z
    np.testing.assert_allclose(rp1.seg_change_z, z1, rtol=1e-9, equal_nan=True)


def test_class_scatter_is_the_runs_scatter_from_segment_to_segment_beyond_the_healthy_one():
    rng = np.random.default_rng(5)
    sigma0 = ALERT / HEALTHY_ALERT_Z
    alert = np.full(SEG.size, ALERT)
    rough = rng.normal(0.0, 0.3, SEG.size)
    out = class_scatter(rough, CLS, alert, SEG)
    assert out[0] == pytest.approx(np.sqrt(0.3**2 - sigma0**2), rel=0.15) and np.all(out == out[0])
    # a smooth line's class scatters by a pass's noise: nothing beyond the healthy scatter
    assert class_scatter(rng.normal(0.0, 0.9 * sigma0, SEG.size), CLS, alert, SEG)[0] < 0.35 * sigma0
    # a few places do not move it, nor does a long extent that departs (a tamped 600 m at -0.3 in a smooth line)
    spiked = rough.copy()
    spiked[:10] = 2.0
    assert class_scatter(spiked, CLS, alert, SEG)[0] == pytest.approx(out[0], rel=0.1)
    smooth = track(np.random.default_rng(6)) + rng.normal(0.0, 0.02, SEG.size) + box(11_000.0, 11_600.0, -0.3)
    assert class_scatter(smooth, CLS, alert, SEG)[0] == 0.0
    # each class its own; too few neighbouring segments with an index, or no class: not known
    two = np.where(SEG < 1150, "slab", "b91").astype(object)
    both = np.where(SEG < 1150, rng.normal(0.0, 0.02, SEG.size), rough)
    got = class_scatter(both, two, np.full(SEG.size, ALERT), SEG)
    assert got[0] == 0.0 and got[-1] > 0.25
    few = np.full(SEG.size, np.nan)
    few[:20] = rough[:20]
    assert np.isnan(class_scatter(few, CLS, alert, SEG)).all()
    gaps = rough.copy()
    gaps[::2] = np.nan  # no two neighbours with an index
    assert np.isnan(class_scatter(gaps, CLS, alert, SEG)).all()
    assert np.isnan(class_scatter(rough, np.full(SEG.size, None, dtype=object), alert, SEG)).all()
    with pytest.raises(ValueError, match="classes"):
        class_scatter(rough, CLS[:5], alert, SEG)


def _rough_run(rough_sd: float, spot: float) -> object:
    """The newest of 11 runs over a line whose rails give every segment its own lasting response (``rough_sd``),
    stated 1-σ 0.14 everywhere, with one segment at km 11.5 reading ``spot`` at every pass."""
    base = np.random.default_rng(21).normal(0.0, rough_sd, SEG.size) if rough_sd > 0 \
        else track(np.random.default_rng(21))
    base = np.clip(base, -0.45, 0.45) if rough_sd > 0 else base
    base[int(np.searchsorted(SEG, 1150))] = spot
    n = 10
    x = runs(np.random.default_rng(22), base, n + 1)
    sd = np.full(x.shape, 0.14)
    days = np.arange(n + 1) * 15.0
    return find_places(SEG, x[:, :, n], x[:, :, :n], days[:n], days[n], CLS, segment_m=10.0, params=PARAMS,
                       index_sd=sd[:, :, n], history_sd=sd[:, :, :n])


def _anomaly_at(rp, m: float) -> bool:
    return any(rp.places.start_m[i] - 10 <= m <= rp.places.end_m[i] + 10 and rp.places.evidence[i] & EVIDENCE_ANOMALY
               for i in range(len(rp.places)))


def test_a_level_within_the_rails_scatter_is_no_place_and_the_same_level_on_smooth_rails_is():
    # +0.6 at every pass, stated 1-σ 0.14: where the class scatters 0.3 across the run (rough rails) it is within
    # what the rails give a typical support; where it scatters as healthy track does it is an anomaly
    rough = _rough_run(0.3, 0.6)
    assert not _anomaly_at(rough, 11_505.0)
    assert rough.seg_level_sd[0] > 0.2  # the level's 1-σ says so
    smooth = _rough_run(0.0, 0.6)
    assert _anomaly_at(smooth, 11_505.0)
    assert smooth.seg_level_sd[0] == pytest.approx(0.14)
    # on rough rails a level far beyond that scatter is still one
    assert _anomaly_at(_rough_run(0.3, 1.6), 11_505.0)
