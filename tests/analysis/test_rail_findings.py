"""Rail findings followed over a line's runs (app.analysis.impacts.findings): identity from the first
sighting, one sighting per run, runs seen out of runs passed, kind from the register or the dip, depth trend."""

from __future__ import annotations

import math

import numpy as np
import pytest

from app.analysis.impacts.findings import (
    SURFACE_MARGIN_M,
    RunImpacts,
    finding_kind,
    follow_findings,
    latest_surface_work,
    run_coverage,
    run_offset,
)


def _run(run_id: int, day: float, impacts, covered=(0.0, 1000.0)) -> RunImpacts:
    return RunImpacts(run_id, day, covered, impacts)


def test_findings_keep_their_identity_and_count_the_runs_that_saw_them():
    runs = [
        _run(1, 0.0, [(100.0, 0.30, 1.0), (400.0, 0.55, 0.4)]),
        _run(2, 14.0, [(100.4, 0.32, 1.0), (700.0, 0.25, 0.9)]),             # 400 missed, a new one at 700
        _run(3, 28.0, [(99.7, 0.34, 1.0), (100.9, 0.2, 1.0), (400.3, 0.6, 0.4), (700.2, 0.26, 1.0)]),
        _run(4, 42.0, [(100.2, 0.36, 1.1)], covered=(0.0, 500.0)),            # did not pass 700
    ]
    found = follow_findings(runs, assets=[{"type": "insulated_joint", "track_m": 401.0, "name": "IJ 7"}])
    assert [(f.first_run_id, f.anchor_m) for f in found] == [(1, 100.0), (3, 100.9), (1, 400.0), (2, 700.0)]
    weld, second, joint, late = found
    assert weld.runs_seen == 4 and weld.runs_passed == 4 and weld.kind == "weld"
    assert [s.run_id for s in weld.sightings] == [1, 2, 3, 4]
    assert second.runs_seen == 1  # one sighting per run: the second impact of run 3 near 100 m is another finding
    assert second.runs_passed == 4  # every run passed it, also the two before run 3 saw it
    assert joint.runs_seen == 2 and joint.runs_passed == 4 and joint.kind == "insulated_joint"
    assert joint.asset["name"] == "IJ 7"
    assert late.runs_seen == 2 and late.runs_passed == 3 and late.kind == "weld"  # run 1 passed it unseen
    tr = weld.depth_trend()
    assert tr.rate_per_year == pytest.approx(0.02 / 14.0 * 365.25, rel=1e-6) and tr.significant
    assert weld.depth_mm == pytest.approx(0.36) and weld.track_m == pytest.approx(100.1)
    # a later run adds to a finding, never changes one that exists
    more = follow_findings([*runs, _run(5, 56.0, [(100.1, 0.37, 1.0)])])
    assert [(f.first_run_id, f.anchor_m) for f in more] == [(f.first_run_id, f.anchor_m) for f in found]
    assert follow_findings(list(reversed(runs)))[0].sightings == weld.sightings  # time order, whatever the input


def test_a_finding_is_steady_where_half_the_runs_that_passed_it_saw_it():
    runs = [_run(k, 14.0 * k, [(100.0, 0.3, 1.0)] + ([(500.0, 0.2, 1.0)] if k in (2, 3) else [])
                 + ([(800.0, 0.4, 1.0)] if k == 4 else [])) for k in range(1, 5)]
    weld, pair, once = follow_findings(runs)
    assert (weld.runs_seen, weld.runs_passed, weld.steady) == (4, 4, True)
    assert (pair.runs_seen, pair.runs_passed, pair.steady) == (2, 4, True)  # half
    assert (once.runs_seen, once.runs_passed, once.steady) == (1, 4, False)


def test_a_run_covers_its_rows_and_finds_only_there():
    """An impact beyond the run's condition rows (a record's end, where the store kept none of its values)
    is no sighting: counted, it made the run pass there while the runs that did not find it had not — issue
    33's line end, a false finding 'seen 3 of 3' by 3 of 24 runs."""
    hits = [(120.0, 0.3, 1.0), (955.0, 0.3, 1.0), (90.0, 0.2, 1.0)]
    covered, inside = run_coverage(hits, (100.0, 950.0))
    assert covered == (100.0, 950.0) and inside == [(120.0, 0.3, 1.0)]
    assert run_coverage(hits, None) == ((90.0, 955.0), hits)  # no rows: the impacts' own extent
    assert all(map(math.isnan, run_coverage([], None)[0]))
    with pytest.raises(ValueError, match="rows_m"):
        run_coverage(hits, (950.0, 100.0))
    # three runs end at 950 m, one at 960 m and finds something at 955 m: it passed it, the others did not
    runs = [_run(k, 14.0 * k, *reversed(run_coverage([(500.0, 0.3, 1.0)], (0.0, 950.0)))) for k in (1, 2, 3)]
    end = _run(4, 56.0, *reversed(run_coverage([(500.0, 0.3, 1.0), (955.0, 0.3, 1.0)], (0.0, 960.0))))
    weld, tail = follow_findings([*runs, end])
    assert weld.runs_passed == 4 and (tail.runs_seen, tail.runs_passed) == (1, 1)


def test_the_kind_of_a_finding():
    assert finding_kind(0.4) == "joint" and finding_kind(1.0) == "weld" and finding_kind(math.nan) == "weld"
    assert finding_kind(1.0, "insulated_joint") == "insulated_joint" and finding_kind(0.3, "weld") == "weld"
    assert finding_kind(0.3, "unknown-thing") == "joint"
    with pytest.raises(ValueError, match="match_m"):
        follow_findings([], match_m=0.0)


def test_a_run_off_by_metres_is_registered_on_the_known_findings():
    """A run whose alignment failed (its km 2.9 m off) finds the same welds: registered on the findings known, its
    sightings join them instead of starting new ones; a run whose impacts agree on no offset is taken as it is."""
    welds = [103.9, 194.6, 284.3, 377.7, 471.5, 575.9, 668.7]
    first = _run(1, 0.0, [(x, 0.3, 1.0) for x in welds])
    off = _run(2, 15.0, [(x + 2.9, 0.3, 1.0) for x in welds[:-1]] + [(830.0, 0.25, 1.0)])
    found = follow_findings([first, off])
    assert [f.runs_seen for f in found] == [2, 2, 2, 2, 2, 2, 1, 1]
    assert found[0].sightings[1].track_m == pytest.approx(103.9) and found[-1].anchor_m == pytest.approx(827.1)
    # both runs covered both: the first passed where the second found a new one, the second where it saw none
    assert found[-1].runs_passed == 2 and found[-2].runs_passed == 2
    # a run that saw it passed it, also where its covered stretch ends short of the anchor
    edge = follow_findings([_run(1, 0.0, [(999.5, 0.3, 1.0)], covered=(0.0, 999.0)),
                            _run(2, 15.0, [(999.6, 0.3, 1.0)], covered=(0.0, 999.9))])
    assert edge[0].runs_seen == 2 and edge[0].runs_passed == 2
    assert run_offset(np.array(welds[:4]) - 2.9, np.array(welds)) == pytest.approx(2.9)
    assert run_offset(np.array([150.0, 333.0, 520.0]), np.array(welds)) == 0.0  # no offset most agree on
    assert len(follow_findings([first, off], register_m=0.0)) == 14  # not registered: each of its 7 a new one


def test_a_depth_trend_starts_anew_after_work_on_the_rail_surface():
    """A grinding changes the dip with the surface (issue 33's real line: 10 of 25 steady findings on the ground
    stretch had a significant depth trend across it, 1 of 129 elsewhere): the trend reads the sightings after it."""
    depth = {100.0: [0.30, 0.30, 0.31, 0.30, 0.20, 0.21, 0.20], 500.0: [0.25, 0.25, 0.26, 0.25, 0.25, 0.26, 0.25]}
    runs = [_run(k + 1, 15.0 * k, [(x, d[k], 1.0) for x, d in depth.items()]) for k in range(7)]
    across, beside = follow_findings(runs)
    assert across.depth_trend().significant and across.depth_trend().rate_per_year < 0  # the work's step
    grinding = [(90.0, 300.0, 50.0)]  # start_m, end_m, day: between the 4th and the 5th run
    ground, untouched = follow_findings(runs, surface_work=grinding)
    assert ground.surface_day == 50.0 and math.isnan(untouched.surface_day)
    assert [s.run_id for s in ground.trend_sightings] == [5, 6, 7]
    assert not ground.depth_trend().significant and abs(ground.depth_trend().rate_per_year) < 0.1
    assert untouched.depth_trend() == beside.depth_trend() and len(untouched.trend_sightings) == 7
    # identity, runs seen and the newest depth do not change with it
    assert (ground.first_run_id, ground.anchor_m, ground.runs_seen, ground.depth_mm) == \
        (across.first_run_id, across.anchor_m, across.runs_seen, across.depth_mm)
    # the latest work counts; one after the newest run leaves no trend (the rail it measured is gone)
    assert follow_findings(runs, surface_work=[*grinding, (0.0, 150.0, 20.0)])[0].surface_day == 50.0
    late = follow_findings(runs, surface_work=[(90.0, 110.0, 200.0)])[0]
    assert late.trend_sightings == [] and math.isnan(late.depth_trend().rate_per_year)


def test_the_work_over_a_position():
    work = [(200.0, 100.0, 10.0), (150.0, 400.0, 30.0), (0.0, 50.0, float("nan"))]
    assert latest_surface_work(120.0, work) == 10.0  # an extent in either order
    assert latest_surface_work(160.0, work) == 30.0  # the latest of two
    assert latest_surface_work(400.0 + SURFACE_MARGIN_M, work) == 30.0  # its ends widened by the margin
    assert math.isnan(latest_surface_work(400.0 + SURFACE_MARGIN_M + 0.1, work))
    assert math.isnan(latest_surface_work(20.0, work))  # no valid day
    assert math.isnan(latest_surface_work(120.0, []))
    with pytest.raises(ValueError, match="margin_m"):
        latest_surface_work(120.0, work, margin_m=-1.0)
