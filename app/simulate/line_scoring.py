"""Scoring what the service answers on a simulated history against its truth (issue 33's targets).

The history (:mod:`app.simulate.history`, e.g. :func:`~app.simulate.history.real_line_history`) knows
what happened to its line: the support changes (:meth:`~app.simulate.history.HistorySpec.truth_places`),
the rail features (:meth:`~app.simulate.history.HistorySpec.rail_features`: welds and joints), the
maintenance actions (:meth:`~app.simulate.history.HistorySpec.maintenance`). The functions here take
what an engineer or a data system reads from the service — the work list (``GET
/condition/places``), the flag feed (``GET /condition/flags``), the maintenance effects (``GET
/condition/maintenance-effect``), as plain dicts — and say how far it is from that truth:

* :func:`score_work_list`: the listed places against the support changes present on a day (how many
  listed, the share of real ones among the first ten, where the developing place ranks and whether it
  has a projected date, whether the new step is listed and how far off, places on a weld or a joint);
* :func:`score_flags`: the false 10 m step flags per speed group, on the ramps and per vehicle;
* :func:`score_effects`: the maintenance effects against the actions' truth (the tamping's effect on
  the support, the grinding's, which is none).

Positions are on the line's km axis (the first run is the store's alignment reference and has no
odometry error, so the store's axis is the truth's). A place or flag is **real** when its extent
overlaps a support change's (the lasting anomalies, the changes and developing places since their day,
the tampings' extents) widened by ``tol_m`` either side — a tamping's extent only within
:data:`TAMPING_NEW_DAYS` of its day, and after that only for a place whose evidence is its level (an
anomaly): the service starts a tamped segment's history anew at the work, so a step or a trend found there
later is measured against the tamped track, not across the work (counted real before, two such places —
seed 1's km 12.71, seed 4's 12.88 — stood among the real ones of the issue-33 bench).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from app.analysis.condition.lifecycle import LifecycleParams
from app.analysis.units import KMH_PER_MPS
from app.simulate.history import HistorySpec, RailFeature, TruthPlace

__all__ = [
    "TOL_M",
    "FEATURE_TOL_M",
    "speed_group",
    "support_truth",
    "place_cause",
    "score_work_list",
    "score_flags",
    "score_effects",
]

#: How far (m) a place or flag may reach beyond a support change's extent and still be real: one 10 m
#: segment (the store's grid does not fall on the truth's ends).
TOL_M = 10.0
#: How close (m) to a weld or joint a place's extent must come to be "on" it: half a 10 m segment.
FEATURE_TOL_M = 5.0
#: How long (days) after a tamping a step or trend over its extent is the tamping's: the places' window for an
#: action's effect (:class:`~app.analysis.condition.lifecycle.LifecycleParams` ``explain_days``).
TAMPING_NEW_DAYS = LifecycleParams().explain_days


def _extent(item: Mapping[str, Any]) -> tuple[float, float]:
    """``(from, to)`` in m on the km axis of an answer with ``km_from`` / ``km_to``."""
    a, b = 1000.0 * float(item["km_from"]), 1000.0 * float(item["km_to"])
    return (a, b) if a <= b else (b, a)


def _gap(a: tuple[float, float], b: tuple[float, float]) -> float:
    """Distance between two extents, m (0 where they overlap)."""
    return max(0.0, a[0] - b[1], b[0] - a[1])


def speed_group(cruise_kmh: float, groups_mps: Sequence[float]) -> int:
    """The speed group (index into ``groups_mps``, m/s) whose speed is nearest a run's cruise speed."""
    v = float(cruise_kmh) / KMH_PER_MPS
    return int(np.argmin([abs(math.log(v / g)) for g in groups_mps]))


def support_truth(spec: HistorySpec, day: float) -> list[TruthPlace]:
    """The support changes present on ``day``: lasting anomalies, changes and developing places since
    their day (not yet repaired), the tampings done (their extent changed too)."""
    return spec.truth_places(day)


def place_cause(spec: HistorySpec, extent: tuple[float, float], day: float, *,
                features: Sequence[RailFeature] | None = None, evidence: Sequence[str] | None = None) -> str:
    """What a place or flag at ``extent`` (m) is, by the truth: ``"real"`` (on a support change; on a tamping's
    extent within :data:`TAMPING_NEW_DAYS` of its day, or later with ``"anomaly"`` in ``evidence``: a flag
    has none), ``"tamped extent"`` (on one later, by a step or a trend), ``"joint"`` / ``"weld"`` (within
    :data:`FEATURE_TOL_M` of one), ``"ramp"`` (on a speed ramp), ``"grinding"`` (on a ground stretch after its
    day), ``"class edge"`` (within 50 m of a change of superstructure), else ``"noise"``; the first that
    applies, in this order."""
    on = [t for t in support_truth(spec, day) if _gap(extent, (t.track_from_m, t.track_to_m)) <= TOL_M]
    level = evidence is not None and "anomaly" in evidence
    if any(t.kind != "tamping" or day - t.since_day <= TAMPING_NEW_DAYS or level for t in on):
        return "real"
    if on:
        return "tamped extent"
    feats = spec.rail_features() if features is None else features
    for kind in ("joint", "weld"):
        if any(f.kind == kind and _gap(extent, (f.track_m, f.track_m)) <= FEATURE_TOL_M for f in feats):
            return kind
    ramp_lo, ramp_hi = spec.ramps()
    if extent[0] < ramp_lo or extent[1] > ramp_hi:
        return "ramp"
    if spec.line.surface is not None:
        for g, gday in zip(spec.line.surface.grindings, spec.grinding_days(), strict=True):
            if gday <= day and _gap(extent, (g.track_from_m, g.track_to_m)) <= TOL_M:
                return "grinding"
    edges = [s.track_from_m for s in spec.line.sections[1:]]
    if any(_gap(extent, (e, e)) <= 50.0 for e in edges):
        return "class edge"
    return "noise"


def score_work_list(spec: HistorySpec, places: Sequence[Mapping[str, Any]], day: float, *,
                    top: int = 10) -> dict[str, Any]:
    """The work list of ``day`` (the places in the order the service ranks them) against the truth.

    Parameters
    ----------
    spec : HistorySpec
    places : sequence of dict
        The listed places, ranked (``GET /condition/places`` items: ``km_from``, ``km_to``,
        ``projected_date``, ``direction``, ``tier``, ...).
    day : float
        The day of the newest run applied (days from ``spec.start``).
    top : int
        How many of the first places the real share is taken over.

    Returns
    -------
    dict
        ``listed``; ``real_truth`` (support changes present: lasting anomalies, changes, developing
        places, tampings), ``listed_per_real``; ``real_listed`` (listed places that are real);
        ``first_real_share`` (of the first ``top``); ``causes`` (how many of each
        :func:`place_cause`); ``on_rail_feature`` (places not real within :data:`FEATURE_TOL_M` of a weld
        or joint); ``developing_rank`` (1-based, None: not listed), ``developing_projected`` (its
        projected date, None without one), ``developing_direction``; ``new_step_listed`` (within 5 m),
        ``new_step_gap_m``, ``new_step_centre_err_m`` (None: no new step on ``day``, or not listed).
    """
    truth = support_truth(spec, day)
    feats = spec.rail_features()
    extents = [_extent(p) for p in places]
    causes = [place_cause(spec, e, day, features=feats, evidence=p.get("evidence"))
              for e, p in zip(extents, places, strict=True)]
    real = np.array([c == "real" for c in causes], dtype=bool)
    head = real[:top]
    out: dict[str, Any] = {
        "listed": len(places), "real_truth": len(truth),
        "listed_per_real": len(places) / len(truth) if truth else math.nan,
        "real_listed": int(real.sum()),
        "first_real_share": float(head.mean()) if head.size else math.nan,
        "causes": {c: causes.count(c) for c in sorted(set(causes))},
        "on_rail_feature": sum(1 for c in causes if c in ("weld", "joint")),
        "developing_rank": None, "developing_projected": None, "developing_direction": None,
        "new_step_listed": None, "new_step_gap_m": None, "new_step_centre_err_m": None,
    }
    for t in truth:
        ext = (t.track_from_m, t.track_to_m)
        hits = [i for i, e in enumerate(extents) if _gap(e, ext) <= TOL_M]
        if t.kind == "developing":
            if hits:
                out["developing_rank"] = hits[0] + 1
                out["developing_projected"] = places[hits[0]].get("projected_date")
                out["developing_direction"] = places[hits[0]].get("direction")
        elif t.kind == "change" and t.since_day > max((r.day for r in spec.runs if r.day < day), default=-math.inf):
            # the change the newest run is the first to see
            gaps = [_gap(e, ext) for e in extents]
            j = int(np.argmin(gaps)) if gaps else -1
            out["new_step_gap_m"] = gaps[j] if gaps else None
            out["new_step_listed"] = bool(gaps) and gaps[j] <= 5.0
            if gaps and gaps[j] <= 5.0:
                out["new_step_centre_err_m"] = abs(0.5 * sum(extents[j]) - t.centre_m)
    return out


def score_flags(spec: HistorySpec, flags: Sequence[Mapping[str, Any]], runs: Sequence[Mapping[str, Any]], *,
                groups_mps: Sequence[float], segment_m: int = 10, kind: str = "step") -> dict[str, Any]:
    """False ``segment_m`` flags of ``kind`` per speed group, on the ramps and per vehicle.

    Parameters
    ----------
    spec : HistorySpec
    flags : sequence of dict
        ``GET /condition/flags`` items (``run_id``, ``km_from``, ``km_to``, ``segment_m``, ``kind``).
    runs : sequence of dict
        The runs scored: ``run_id``, ``index`` (into ``spec.runs``) and ``tested`` (the segment numbers
        the store tested in that run: a step score on at least one wheel).
    groups_mps : sequence of float
        The speed groups' cruise speeds, m/s (:func:`speed_group`).

    Returns
    -------
    dict
        Per key ``"<v> m/s"`` (cruise stretch of the runs of that group), ``"ramps"`` (the ramps of every
        run) and ``"vehicle <id>"`` (every segment of that vehicle's runs): ``tested`` segments, ``false``
        flags, ``share`` (false / tested), ``real`` flags; ``false_flags``: every false flag as
        ``(run index, km_from, cause)``.
    """
    ramp_lo, ramp_hi = spec.ramps()
    feats = spec.rail_features()
    by_run: dict[int, list[tuple[float, float]]] = {}
    for f in flags:
        if int(f["segment_m"]) == segment_m and f["kind"] == kind:
            by_run.setdefault(int(f["run_id"]), []).append(_extent(f))
    out: dict[str, Any] = {}
    false_list: list[tuple[int, float, str]] = []

    def add(key: str, tested: int, false: int, real: int) -> None:
        row = out.setdefault(key, {"tested": 0, "false": 0, "real": 0})
        row["tested"] += tested
        row["false"] += false
        row["real"] += real

    for r in runs:
        run = spec.runs[int(r["index"])]
        seg = np.asarray(sorted(r["tested"]), dtype=np.int64)
        centre = (seg + 0.5) * segment_m
        on_ramp = (centre < ramp_lo) | (centre > ramp_hi)
        g = f"{groups_mps[speed_group(run.cruise_kmh, groups_mps)]:g} m/s"
        veh = f"vehicle {spec.vehicle_of(run).vehicle_id}"
        cause = [place_cause(spec, e, run.day, features=feats) for e in by_run.get(int(r["run_id"]), [])]
        ext = by_run.get(int(r["run_id"]), [])
        ramp_flag = [e[0] < ramp_lo or e[1] > ramp_hi for e in ext]
        false = [c != "real" for c in cause]
        add(g, int((~on_ramp).sum()), sum(f and not rf for f, rf in zip(false, ramp_flag, strict=True)),
            sum((not f) and not rf for f, rf in zip(false, ramp_flag, strict=True)))
        add("ramps", int(on_ramp.sum()), sum(f and rf for f, rf in zip(false, ramp_flag, strict=True)),
            sum((not f) and rf for f, rf in zip(false, ramp_flag, strict=True)))
        add(veh, int(seg.size), sum(false), len(false) - sum(false))
        false_list += [(int(r["index"]), e[0] / 1000.0, c) for e, c in zip(ext, cause, strict=True) if c != "real"]
    for row in out.values():
        row["share"] = row["false"] / row["tested"] if row["tested"] else math.nan
    out["false_flags"] = false_list
    return out


def score_effects(spec: HistorySpec, effects: Sequence[Mapping[str, Any]], *,
                  value: str = "recovery_pct") -> list[dict[str, Any]]:
    """The maintenance effects the service reports against the actions' truth.

    Parameters
    ----------
    spec : HistorySpec
    effects : sequence of dict
        ``GET /condition/maintenance-effect`` items (``type``, ``km_from``, ``km_to``, ``date`` and
        ``value``).
    value : str
        The item's field holding the effect on the support in per cent of the amplitude.

    Returns
    -------
    list of dict
        Per action: ``type``, ``date``, ``truth_pct`` (a tamping: its factor on the typical track of its
        extent, :meth:`HistorySpec.tamping_effect`; a grinding: 0, the support is unchanged),
        ``reported_pct``, ``error_pp`` (reported − truth, percentage points; None where not reported).
    """
    tampings = {(round(c.track_from_m / 1000.0, 6), round(c.track_to_m / 1000.0, 6)): c
                for c in spec.changes if c.kind == "tamping"}
    out = []
    for e in effects:
        key = (round(float(e["km_from"]), 6), round(float(e["km_to"]), 6))
        if e["type"] == "tamping" and key in tampings:
            truth = 100.0 * math.expm1(spec.tamping_effect(tampings[key]))
        elif e["type"] == "grinding":
            truth = 0.0
        else:
            continue
        rep = e.get(value)
        out.append({"type": e["type"], "date": e["date"], "truth_pct": truth,
                    "reported_pct": None if rep is None else float(rep),
                    "error_pp": None if rep is None else float(rep) - truth})
    return out
