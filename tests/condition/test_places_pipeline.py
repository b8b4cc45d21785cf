"""The places' targets on a history through the real pipeline: 10 runs of a planted history (speed ramps,
cruise speeds ±10 %, odometry errors, three superstructure classes, lasting soft and hard spots, two new
20 m changes, a developing place and a tamping over it) uploaded, processed by the local worker and
published into the condition store; the places of each run from the store's 10 m rows as the publish
step will see them (curves fitted on the runs up to it), the lifecycle over the runs."""

from __future__ import annotations

import math

import numpy as np
import pytest

from app.analysis.condition.extent_level import extent_level
from app.analysis.condition.interventions import latest_action_days
from app.analysis.condition.lifecycle import (
    Action,
    LifecycleParams,
    PassHistory,
    advance_places,
    place_outlook,
)
from app.analysis.condition.maintenance_effect import action_effect
from app.analysis.condition.run_places import DEFAULT_PLACE_PARAMS, find_places, segment_index
from app.analysis.condition.segment_curves import fit_segment_curves
from app.analysis.condition.tiers import rank_places
from app.simulate.history import planted_history
from tests.condition.history_support import StoredRun, history_service, process_history, stored_runs

pytestmark = pytest.mark.slow

SEG_M = 10.0


def _curves(runs: list[StoredRun]) -> dict:
    parts = [(r.seg, r.log_amp[i], r.speed[i], np.full(r.seg.size, r.run_id), np.full(r.seg.size, w), r.classes)
             for r in runs for i, w in enumerate(r.wheels)]
    return fit_segment_curves(*[np.concatenate([p[j] for p in parts]) for j in range(6)])


def _wheel_mean(a: np.ndarray) -> np.ndarray:
    n = np.isfinite(a).sum(axis=0)
    return np.where(n > 0, np.nansum(a, axis=0) / np.maximum(n, 1), np.nan)


def _on(src: StoredRun, dst: StoredRun, values: np.ndarray) -> np.ndarray:
    out = np.full((len(dst.wheels), dst.seg.size), np.nan)
    j = np.minimum(np.searchsorted(src.seg, dst.seg), src.seg.size - 1)
    hit = src.seg[j] == dst.seg
    for i, w in enumerate(dst.wheels):
        if w in src.wheels:
            out[i, hit] = values[src.wheels.index(w), j[hit]]
    return out


@pytest.fixture(scope="module")
def history(tmp_path_factory):
    spec = planted_history(seed=3, n_runs=10)
    tmp = tmp_path_factory.mktemp("places-history")
    with history_service(tmp) as client:
        processed = process_history(client, spec, tmp / "files")
        runs = stored_runs(client.settings.database_url, spec)
        service = _service_answers(client, spec, processed)
    assert len(runs) == 10
    return spec, runs, *lifecycle_of(spec, runs), service


def _service_answers(client, spec, processed) -> dict:
    """What the service made of the history in the publish step: the jobs' places summaries, the work
    list (open places and all listed ones) and every listed place's history."""
    url = "/api/v1/condition/places"
    open_ = client.get(url, params={"line_id": spec.line_id, "limit": 1000}).json()
    every = client.get(url, params={"line_id": spec.line_id, "limit": 1000, "include_closed": True}).json()
    missing = client.get(f"{url}/999999/passes")
    return {"summaries": [j["meta"]["condition"]["places"] for j in processed.jobs], "open": open_["items"],
            "all": every["items"], "history": {p["id"]: client.get(f"{url}/{p['id']}").json()
                                              for p in every["items"]},
            "passes": {p["id"]: client.get(f"{url}/{p['id']}/passes").json() for p in every["items"]},
            "missing_passes": (missing.status_code, missing.json())}


def lifecycle_of(spec, runs: list[StoredRun]):
    """The places of each run as the publish step will find them and the lifecycle over the runs."""
    actions = [Action(i + 1, c.track_from_m, c.track_to_m, c.day) for i, c in enumerate(spec.changes)
               if c.kind == "tamping"]
    known, next_id, steps = [], 1, []
    for k, run in enumerate(runs):
        curves = _curves(runs[: k + 1])
        idx = segment_index(run.log_amp, run.speed, run.classes, curves)
        hist = np.stack([_on(runs[j], run, segment_index(runs[j].log_amp, runs[j].speed, runs[j].classes, curves))
                         for j in range(k)], axis=2) if k else np.zeros((*idx.shape, 0))
        days = np.array([r.day for r in runs[:k]])
        # with the store's stated 1-sigma, as the publish step grades them
        hist_sd = np.stack([_on(runs[j], run, runs[j].index_sd) for j in range(k)], axis=2) if k \
            else np.zeros((*idx.shape, 0))
        hist_v = np.stack([_on(runs[j], run, runs[j].speed) for j in range(k)], axis=2) if k \
            else np.zeros((*idx.shape, 0))
        # the history starts anew after the tamping on its segments, as the publish step reads it
        support = latest_action_days(run.seg, SEG_M, np.array([a.start_m for a in actions]),
                                     np.array([a.end_m for a in actions]), np.array([a.day for a in actions]), run.day)
        # compared with the matched passes (one vehicle: the same speed), as the publish step compares them
        rp = find_places(run.seg, idx, hist, days, run.day, run.classes, segment_m=SEG_M, params=DEFAULT_PLACE_PARAMS,
                         index_sd=run.index_sd, history_sd=hist_sd, speed=run.speed, history_speed=hist_v,
                         support_days=support)
        covered = (float(run.seg.min() * SEG_M), float((run.seg.max() + 1) * SEG_M))
        passes = PassHistory.of(hist, hist_v, run.speed, days, DEFAULT_PLACE_PARAMS.change_params(),
                                support_days=support)
        events, _, next_id = advance_places(known, rp, run_id=run.run_id, day=run.day, covered_m=covered,
                                            params=LifecycleParams(), next_id=next_id,
                                            place_params=DEFAULT_PLACE_PARAMS, actions=actions, passes=passes)
        listed = [(p.id, p.start_m, p.end_m, p.tier, p.observations[-1].severity,
                   place_outlook(p, DEFAULT_PLACE_PARAMS.levels).projection.days, p.observations[-1].centre_m,
                   p.direction)
                  for p in known if p.listed and p.active]
        steps.append({"run": run, "places": rp, "events": events, "listed": listed})
    return known, steps, actions


def _real(spec, day: float, a: float, b: float, tol: float = 10.0) -> bool:
    return any(t.track_from_m < b + tol and a - tol < t.track_to_m for t in spec.truth_places(day))


def test_the_work_list_is_real_places_and_nothing_on_the_ramps(history):
    spec, runs, _, steps, _, _ = history
    ramp_lo = spec.km_start * 1000 + spec.ramp_in_m
    ramp_hi = spec.km_start * 1000 + spec.length_km * 1000 - spec.ramp_out_m
    for st in steps[5:]:
        day, listed = st["run"].day, st["listed"]
        assert listed
        order = rank_places(np.array([x[3] for x in listed]), np.array([x[5] for x in listed]),
                            np.array([x[4] for x in listed]))
        first10 = [listed[i] for i in order[:10]]
        real = [_real(spec, day, x[1], x[2]) for x in first10]
        assert np.mean(real) >= 0.8, (day, first10)
        assert all(r or ramp_lo <= x[1] and x[2] <= ramp_hi for r, x in zip(real, first10, strict=True))


def test_each_new_20m_change_is_one_place_within_5m(history):
    spec, _, _, steps, _, _ = history
    changes = [c for c in spec.changes if c.kind == "change"]
    for c in changes:
        centre = 0.5 * (c.track_from_m + c.track_to_m)
        direction = 1 if c.factor > 1 else -1
        after = [st for st in steps if st["run"].day > c.day]
        # the first run after it finds it: one place, within 5 m
        p = after[0]["places"].places
        hit = [i for i in range(len(p)) if p.start_m[i] < c.track_to_m + 10 and c.track_from_m - 10 < p.end_m[i]]
        assert len(hit) == 1 and abs(p.centre_m[hit[0]] - centre) <= 5.0 and p.direction[hit[0]] == direction
        # from the second on it is one place of the work list, within 5 m, on every run
        for st in after[1:]:
            on = [x for x in st["listed"] if x[1] < c.track_to_m + 10 and c.track_from_m - 10 < x[2]]
            assert len(on) == 1, (st["run"].day, c, on)
            assert abs(on[0][6] - centre) <= 5.0 and on[0][7] == direction


def test_the_tamping_closes_its_place_and_its_effect_is_within_5_points(history):
    spec, runs, known, steps, actions, _ = history
    (tamping,) = actions
    first_after = next(k for k, st in enumerate(steps) if st["run"].day > tamping.day)
    repaired = [e for e in steps[first_after]["events"] if e.kind == "repaired"]
    assert [e.action_id for e in repaired] == [tamping.id]
    place = next(p for p in known if p.id == repaired[0].place_id)
    dev = next(c for c in spec.changes if c.kind == "developing")
    assert place.start_m < dev.track_to_m and dev.track_from_m < place.end_m and place.direction == 1
    assert not place.active and place.actions == [tamping.id]
    assert any(x[0] == place.id for x in steps[first_after - 1]["listed"])  # it was on the list before
    assert all(x[0] != place.id for st in steps[first_after:] for x in st["listed"])
    # the tamping's own effect (its extent 20 % lower) is its record, never listed
    effect = [p for p in known if p.explained_by == tamping.id]
    assert all(not p.listed for p in effect)
    # its effect: the extent against the track around it, run by run, with the curves of all runs
    curves = _curves(runs)
    vals = [extent_level(r.seg, _wheel_mean(segment_index(r.log_amp, r.speed, r.classes, curves)),
                         tamping.start_m, tamping.end_m, segment_m=SEG_M) for r in runs]
    eff = action_effect(np.array([r.day for r in runs]), np.array(vals), tamping.day)
    truth = 100 * math.expm1(spec.tamping_effect(next(c for c in spec.changes if c.kind == "tamping")))
    assert 100 * math.expm1(eff.recovery) == pytest.approx(truth, abs=5.0)


def test_alerts_only_for_new_places_and_tier_changes(history):
    spec, _, known, steps, _, _ = history
    by_id = {p.id: p for p in known}
    news = [(st["run"].day, e) for st in steps for e in st["events"] if e.kind == "new"]
    assert news and all(_real(spec, day, by_id[e.place_id].start_m, by_id[e.place_id].end_m) for day, e in news)
    assert len({e.place_id for _, e in news}) == len(news)  # once per place
    for st in steps:
        for e in st["events"]:
            assert e.kind in ("new", "tier", "repaired", "back")
            if e.kind == "tier":
                assert e.old_tier != e.new_tier
    # far fewer alerts than runs × places: a place on the list raises none while nothing changes
    n_events = sum(len(st["events"]) for st in steps)
    assert n_events <= 2 * len([p for p in known if p.listed])


def test_the_publish_step_keeps_the_same_places_as_the_lifecycle(history):
    """The service (the publish step of each run, both worker modes' one path) lists the places the
    lifecycle over the store's rows finds, with their tiers; the tamping's place is fixed with the
    action, by the service, and its history holds every run that saw it."""
    spec, runs, known, steps, actions, service = history
    assert all(s["applied"] for s in service["summaries"]), service["summaries"]
    pure = sorted((round(x[1]), round(x[2]), x[7], x[3]) for x in steps[-1]["listed"])

    def served(confirmed: bool) -> list:
        return sorted((round(p["km_from"] * 1000), round(p["km_to"] * 1000), 1 if p["direction"] == "hard" else -1,
                       ["watch", "alert", "intervention", "immediate"].index(p["tier"])) for p in service["open"]
                      if p["confirmed"] is confirmed)

    assert served(True) == pure
    # the new places (found by the newest run covering them, not yet confirmed) are on the list too
    new = sorted((round(p.start_m), round(p.end_m), p.direction, p.tier) for p in known
                 if not p.listed and p.active and p.misses == 0 and p.explained_by is None)
    assert served(False) == new
    (tamping,) = actions
    fixed = [p for p in service["all"] if p["status"] == "fixed"]
    assert len(fixed) == 1 and not fixed[0]["active"] and fixed[0]["status_by"] == "trackvkf"
    assert [(a["kind"], a["relation"]) for a in fixed[0]["actions"]] == [("tamping", "repaired")]
    assert fixed[0]["km_from"] * 1000 < tamping.end_m and tamping.start_m < fixed[0]["km_to"] * 1000
    h = service["history"][fixed[0]["id"]]
    assert [e["kind"] for e in h["events"]].count("repaired") == 1 and h["status_history"][-1]["new"] == "fixed"
    assert [m["kind"] for m in h["maintenance"]] == ["tamping"]
    for p in service["all"]:
        obs = service["history"][p["id"]]["observations"]
        assert len(obs) == p["runs_confirming"] and p["method_version"] == obs[-1]["method_version"]
    # the service's alerts are the lifecycle's events of listed places: news once per place, all real
    news = [e for s in service["summaries"] for e in s["events"] if e["kind"] == "new"]
    assert len(news) == len({e["place_id"] for e in news}) == len([p for p in known if p.listed])


def test_a_place_shows_the_passes_it_was_read_against(history):
    """``GET …/places/{id}/passes``: the segment a place is read at in its newest run (its peak: the place's level;
    a developing place: a segment of it), the earlier runs before it, the matched passes are those the place's change was read against (a place
    found by a step has some), and a place found by its trend states the line through them, at the rate the
    place was given (within that rate's 95 % interval: the line is fitted on the rows as stored now)."""
    spec, runs, known, steps, actions, service = history
    code, body = service["missing_passes"]
    assert code == 404 and "999999" in str(body), body
    trended = 0
    for p in service["all"]:
        pp = service["passes"][p["id"]]
        obs = service["history"][p["id"]]["observations"][-1]
        assert pp["place_id"] == p["id"] and pp["run_id"] == obs["run_id"] == p["last_run_id"]
        (this,) = [x for x in pp["passes"] if x["this_run"]]
        assert this == pp["passes"][-1] and this["run_id"] == p["last_run_id"] and this["matched_index"] == this["index"]
        if pp["at"] == "peak":  # read at its peak: the place's level
            assert pp["km_from"] <= obs["peak_km"] < pp["km_to"], (pp, obs)
            assert math.isclose(this["index"], obs["level"], abs_tol=1e-6)
        else:  # a developing place that does not grow at its peak: where it grows fastest, inside it
            assert pp["at"] == "trend" and "trend" in obs["evidence"]
            assert obs["km_from"] <= pp["km_from"] < obs["km_to"], (pp, obs)
        times = [x["run_time"] for x in pp["passes"]]
        assert times == sorted(times) and len(set(times)) == len(times)
        earlier = [x for x in pp["passes"][:-1] if x["matched_index"] is not None]
        if "step" in obs["evidence"]:
            assert earlier, p
        if "trend" in obs["evidence"]:
            tr = pp["trend"]
            assert tr is not None and tr["n"] == len(earlier) + 1, tr
            sign = 1 if p["direction"] == "hard" else -1
            assert tr["rate_low"] <= sign * p["rate_per_year"] <= tr["rate_high"], (tr, p["rate_per_year"])
            assert tr["from_time"] == earlier[0]["run_time"] and tr["to_time"] == this["run_time"]
            trended += 1
        else:
            assert pp["trend"] is None
    assert trended >= 1
