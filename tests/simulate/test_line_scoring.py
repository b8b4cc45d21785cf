"""Scoring the service's answers against a history's truth (app.simulate.line_scoring): what counts as a
real place, what a place on a weld or a ramp is, the developing place's rank, the new step's distance, the
false flags per speed group and the maintenance effects."""

from __future__ import annotations

import math

import numpy as np
import pytest

from app.simulate.history import REAL_LINE_SPEEDS_MPS, real_line_history
from app.simulate.line_scoring import (
    TAMPING_NEW_DAYS,
    place_cause,
    score_effects,
    score_flags,
    score_work_list,
    speed_group,
)

SPEC = real_line_history(seed=0)
LAST = SPEC.runs[-1].day


def _place(a_m: float, b_m: float, **kw) -> dict:
    return {"km_from": a_m / 1000.0, "km_to": b_m / 1000.0, "projected_date": None, "direction": "soft", **kw}


def _truth(kind: str):
    return next(t for t in SPEC.truth_places(LAST) if t.kind == kind)


def _weld_away_from_truth() -> float:
    truth = SPEC.truth_places(LAST)
    lo, hi = SPEC.ramps()
    for f in SPEC.rail_features():
        if f.kind == "weld" and lo + 60 < f.track_m < hi - 60 and all(
                f.track_m < t.track_from_m - 30 or f.track_m > t.track_to_m + 30 for t in truth) and all(
                abs(f.track_m - s.track_from_m) > 80 for s in SPEC.line.sections[1:]) and not (
                13_490 < f.track_m < 14_010):
            return f.track_m
    raise AssertionError("no weld away from everything")


def test_a_work_list_is_scored_against_the_support_truth():
    soft, dev, step = _truth("anomaly"), _truth("developing"), _truth("change")
    weld = _weld_away_from_truth()
    seg = 10.0 * math.floor(weld / 10.0)
    places = [
        _place(seg, seg + 10.0),                                            # on a weld: not real
        _place(soft.track_from_m, soft.track_to_m + 10.0),                   # the soft spot
        _place(SPEC.ramps()[0] - 100.0, SPEC.ramps()[0] - 90.0),             # on the acceleration ramp
        _place(dev.track_from_m, dev.track_to_m, projected_date="2026-03-01"),
        _place(step.track_to_m + 3.0, step.track_to_m + 13.0),               # 3 m beside the new step
    ]
    s = score_work_list(SPEC, places, LAST)
    assert s["listed"] == 5 and s["real_truth"] == 4 and s["listed_per_real"] == pytest.approx(1.25)
    assert s["real_listed"] == 3 and s["first_real_share"] == pytest.approx(0.6)
    assert s["causes"] == {"real": 3, "weld": 1, "ramp": 1}
    assert s["on_rail_feature"] == 1
    assert (s["developing_rank"], s["developing_projected"], s["developing_direction"]) == (4, "2026-03-01", "soft")
    assert s["new_step_listed"] is True and s["new_step_gap_m"] == pytest.approx(3.0)
    assert s["new_step_centre_err_m"] == pytest.approx(abs(step.track_to_m + 8.0 - step.centre_m))
    # the new step 12 m off is not listed; on the run before it there is no new step to list
    far = score_work_list(SPEC, [_place(step.track_to_m + 12.0, step.track_to_m + 22.0)], LAST)
    assert far["new_step_listed"] is False and far["new_step_gap_m"] == pytest.approx(12.0)
    assert score_work_list(SPEC, places, SPEC.runs[-2].day)["new_step_listed"] is None
    empty = score_work_list(SPEC, [], LAST)
    assert empty["listed"] == 0 and math.isnan(empty["first_real_share"]) and empty["developing_rank"] is None


def test_causes_of_places_that_are_not_real():
    ground = SPEC.line.surface.grindings[0]
    mid = 0.5 * (ground.track_from_m + ground.track_to_m)
    (gday,) = SPEC.grinding_days()
    joint = next(f for f in SPEC.rail_features() if f.kind == "joint")
    assert place_cause(SPEC, (joint.track_m - 2.0, joint.track_m + 8.0), LAST) == "joint"
    cause = place_cause(SPEC, (mid, mid + 10.0), gday + 1.0)
    assert cause in ("grinding", "weld")  # a weld may lie there too; a weld wins
    if cause == "grinding":
        assert place_cause(SPEC, (mid, mid + 10.0), gday - 1.0) == "noise"
    edge = SPEC.line.sections[2].track_from_m
    assert place_cause(SPEC, (edge + 20.0, edge + 30.0), LAST) in ("class edge", "weld")


def test_a_tamped_extent_is_real_within_the_window_or_by_its_level():
    """A step or trend found on a tamped extent after the places' window for an action's effect is measured
    against the tamped track (the service starts its history anew), not across the work."""
    tamp = _truth("tamping")
    ext = (tamp.track_from_m + 50.0, tamp.track_from_m + 60.0)
    assert place_cause(SPEC, ext, tamp.since_day + 15.0) == "real"
    assert place_cause(SPEC, ext, tamp.since_day + TAMPING_NEW_DAYS + 1.0) == "tamped extent"  # a flag: no evidence
    assert place_cause(SPEC, ext, LAST, evidence=["step"]) == "tamped extent"
    assert place_cause(SPEC, ext, LAST, evidence=["anomaly", "step"]) == "real"
    assert place_cause(SPEC, ext, tamp.since_day - 1.0) != "real"  # before the work, nothing was planted there
    s = score_work_list(SPEC, [_place(*ext, evidence=["step"]), _place(*ext, evidence=["anomaly"])], LAST)
    assert s["causes"] == {"tamped extent": 1, "real": 1} and s["real_truth"] == 4


def test_false_flags_per_speed_group_on_the_ramps_and_per_vehicle():
    n = len(SPEC.runs)
    lo, hi = SPEC.ramps()
    runs = [{"run_id": 100 + i, "index": i, "tested": set(range(1200, 1500))} for i in range(n - 4, n)]
    soft = _truth("anomaly")
    weld = _weld_away_from_truth()
    flags = [
        {"run_id": 999, "km_from": 13.300, "km_to": 13.310, "segment_m": 10, "kind": "step"},  # a run not scored
        {"run_id": 100 + n - 1, "km_from": _truth("change").track_from_m / 1000, "km_to":
            _truth("change").track_from_m / 1000 + 0.01, "segment_m": 10, "kind": "step"},          # real
        {"run_id": 100 + n - 2, "km_from": weld / 1000, "km_to": weld / 1000 + 0.01, "segment_m": 10,
         "kind": "step"},                                                                             # false
        {"run_id": 100 + n - 3, "km_from": (lo - 50) / 1000, "km_to": (lo - 40) / 1000, "segment_m": 10,
         "kind": "step"},                                                                             # ramp
        {"run_id": 100 + n - 3, "km_from": soft.track_from_m / 1000, "km_to": soft.track_from_m / 1000 + 0.01,
         "segment_m": 100, "kind": "step"},                                                           # 100 m
    ]
    out = score_flags(SPEC, flags, runs, groups_mps=REAL_LINE_SPEEDS_MPS)
    tested = {g: 0 for g in ("26 m/s", "40 m/s", "ramps")}
    for r in runs:
        seg = np.array(sorted(r["tested"]))
        c = (seg + 0.5) * 10.0
        ramp = (c < lo) | (c > hi)
        g = f"{REAL_LINE_SPEEDS_MPS[speed_group(SPEC.runs[r['index']].cruise_kmh, REAL_LINE_SPEEDS_MPS)]:g} m/s"
        tested[g] += int((~ramp).sum())
        tested["ramps"] += int(ramp.sum())
    for g, t in tested.items():
        assert out.get(g, {"tested": 0})["tested"] == t
    assert sum(out[g]["false"] for g in ("26 m/s", "40 m/s") if g in out) == 1  # the weld
    assert out["ramps"]["false"] == 1 and sum(out[g]["real"] for g in out if g.endswith("m/s")) == 1
    assert sum(v["tested"] for k, v in out.items() if k.startswith("vehicle")) == 4 * 300
    causes = sorted(c for _, _, c in out["false_flags"])
    assert len(causes) == 2 and "weld" in causes and set(causes) <= {"weld", "ramp", "joint"}


def test_maintenance_effects_against_the_actions_truth():
    m = SPEC.maintenance()
    items = [{"type": r["type"], "date": r["date"], "km_from": r["km_from"], "km_to": r["km_to"],
              "recovery_pct": v} for r, v in zip(m.to_dict("records"), (-10.6, -26.6), strict=True)]
    items.append({"type": "ballast_cleaning", "date": "2025-01-01", "km_from": 12.0, "km_to": 12.1,
                  "recovery_pct": 3.0})
    out = score_effects(SPEC, items)
    assert [e["type"] for e in out] == ["tamping", "grinding"]
    tamp, grind = out
    assert tamp["truth_pct"] == pytest.approx(-20.0, abs=0.5) and tamp["error_pp"] == pytest.approx(
        -10.6 - tamp["truth_pct"])
    assert grind["truth_pct"] == 0.0 and grind["error_pp"] == pytest.approx(-26.6)
    assert score_effects(SPEC, [{**items[0], "recovery_pct": None}])[0]["error_pp"] is None
