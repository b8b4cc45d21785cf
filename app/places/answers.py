"""A place as the API, the exports and the alerts answer it (``/work/briefs/places-contract.md``:
``Place``). One shape for every reader."""

from __future__ import annotations

import datetime as dt
import math
from collections.abc import Sequence
from typing import Any

from app.analysis.condition.places import EVIDENCE_ANOMALY, EVIDENCE_STEP, EVIDENCE_TREND
from app.analysis.condition.reading import amplitude_percent_per_year, direction_words
from app.analysis.condition.tiers import TIER_ACTIONS, TIER_NAMES
from app.core.jsonable import finite_or_none, iso_time
from app.db.models import (
    PLACE_ACTION_RELATIONS,
    PLACE_EVENT_KINDS,
    ConditionLine,
    Place,
    PlaceAction,
)

__all__ = ["QUANTITY", "EVIDENCE_NAMES", "NO_PROJECTION", "PLACE_EVENT_KINDS", "PLACE_ACTION_RELATIONS", "place_dict", "action_dict", "evidence_names", "tier_name"]

#: What every value of a place is: the speed-conditioned stiffness index.
QUANTITY = "stiffness index ln(A/A_ref(class, v))"
#: Evidence bits and their names.
EVIDENCE_NAMES: tuple[tuple[int, str], ...] = ((EVIDENCE_ANOMALY, "anomaly"), (EVIDENCE_STEP, "step"),
                                                (EVIDENCE_TREND, "trend"))


def evidence_names(bits: int) -> list[str]:
    """Names of the evidence bits."""
    return [name for bit, name in EVIDENCE_NAMES if bits & bit]


def tier_name(tier: int | None) -> str | None:
    """The tier's name (None for None)."""
    return None if tier is None else TIER_NAMES[int(tier)]


def action_dict(a: PlaceAction) -> dict[str, Any]:
    """A maintenance action linked to a place."""
    return {"id": a.action_id, "kind": a.kind, "date": a.date.isoformat(), "km_from": a.km_from, "km_to": a.km_to,
            "relation": a.relation}


def _date(t: dt.datetime | None, days: float | None) -> str | None:
    if t is None or days is None or not math.isfinite(days):
        return None
    try:
        return iso_time(t + dt.timedelta(days=float(days)))
    except OverflowError:
        return None


def _amplitude_interval(direction: int, low: float | None, high: float | None) -> dict[str, float | None]:
    """The 95 % interval of the severity's rate as the amplitude's change a year, per cent, low ≤ high."""
    a, b = (amplitude_percent_per_year(direction, x) for x in (low, high))
    if a is None or b is None:
        return {"amplitude_percent_low": None, "amplitude_percent_high": None}
    return {"amplitude_percent_low": min(a, b), "amplitude_percent_high": max(a, b)}


#: Why a place shows no time to limit (``no_projection``): it is at the top tier, its class has no limit
#: above, its trend has too few runs (fewer than 3), or its trend is stable or shrinking (not significant
#: towards the limit).
NO_PROJECTION: tuple[str, ...] = ("top_tier", "no_limit", "too_few_runs", "stable", "shrinking")


def _outlook(p: Place, nxt: str | None) -> dict[str, Any]:
    """The time to the next tier's limit with its 95 % interval (the days at the fast and the slow end of the
    rate's interval: ``days · rate / rate_high`` and ``days · rate / rate_low``; no late end where the slow
    end does not grow), and where there is none, why (:data:`NO_PROJECTION`)."""
    days = finite_or_none(p.days_to_next) if nxt else None
    out: dict[str, Any] = {"next_tier": nxt, "next_limit": finite_or_none(p.next_limit) if nxt else None,
                           "projected_date": _date(p.last_confirmed, days), "days_to_next_tier": days,
                           "days_to_next_tier_early": None, "days_to_next_tier_late": None,
                           "projected_date_early": None, "projected_date_late": None, "no_projection": None}
    rate, low, high = (finite_or_none(x) for x in (p.rate_per_year, p.rate_low, p.rate_high))
    if days is not None:
        if rate is not None and high is not None and high > 0:
            out["days_to_next_tier_early"] = days * rate / high
        if rate is not None and low is not None and low > 0:
            out["days_to_next_tier_late"] = days * rate / low
        out["projected_date_early"] = _date(p.last_confirmed, out["days_to_next_tier_early"])
        out["projected_date_late"] = _date(p.last_confirmed, out["days_to_next_tier_late"])
    elif nxt is None:
        out["no_projection"] = "top_tier"
    elif out["next_limit"] is None:
        out["no_projection"] = "no_limit"
    else:
        out["no_projection"] = {"new": "too_few_runs", "shrinking": "shrinking"}.get(p.tendency or "new", "stable")
    return out


def place_dict(p: Place, line: ConditionLine, actions: Sequence[PlaceAction] = (),
               assets: Sequence[dict[str, Any]] = (), muted_reason: str | None = None,
               speed_kmh: float | None = None) -> dict[str, Any]:
    """The contract's ``Place``: extent in km, peak (the index at the peak segment, ln units, and in
    per cent), tier and its action, evidence, wheels, runs, ``confirmed`` (False: a new place found by one run,
    to be confirmed by the next), outlook, status, actions, assets; and the
    stated 1-σ of the peak, the change and the severity (``peak_sd``, ``change_sd``, ``severity_sd``; None:
    none stated).

    ``direction`` is the index's side (``hard``: above typical track, ``soft``: below); ``reading`` says it in
    the words the physics supports at ``speed_kmh``, the speed of the latest reading
    (:func:`~app.analysis.condition.reading.direction_words`: stiffer / softer only from 42 m/s, else higher /
    lower amplitude). ``rate_per_year`` (and its 95 % interval ``rate_low`` … ``rate_high``) is in ln units a
    year of the severity (``direction · index``; positive: growing); ``amplitude_percent_per_year`` the same as
    the amplitude's change, per cent a year (``100 · expm1(direction · rate)``), ``amplitude_percent_low`` …
    ``amplitude_percent_high`` its interval. ``days_to_next_tier`` (and ``projected_date``) is the time to the next
    tier's limit at the fitted rate, ``…_early`` / ``…_late`` at the ends of the rate's 95 % interval;
    ``no_projection`` says why there is none (:data:`NO_PROJECTION`)."""
    tier = TIER_NAMES[int(p.tier)]
    nxt = TIER_NAMES[int(p.tier) + 1] if int(p.tier) + 1 < len(TIER_NAMES) else None
    level = float(p.level)
    return {
        "id": p.id, "line_id": line.line_id, "track": line.track,
        "km_from": p.start_m / 1000.0, "km_to": p.end_m / 1000.0, "length_m": p.end_m - p.start_m,
        "peak": level, "peak_km": p.peak_m / 1000.0, "peak_percent": 100.0 * math.expm1(level),
        "direction": "hard" if p.direction > 0 else "soft",
        "reading": direction_words(1 if p.direction > 0 else -1, None if speed_kmh is None else speed_kmh / 3.6),
        "speed_kmh": finite_or_none(speed_kmh),
        "tier": tier, "action": TIER_ACTIONS[tier], "evidence": evidence_names(int(p.evidence)),
        "wheels": [w for w in (p.wheel_labels or "").split(",") if w],
        "change": finite_or_none(p.change), "severity": finite_or_none(p.severity), "class": p.cls,
        "peak_sd": finite_or_none(p.level_sd), "change_sd": finite_or_none(p.change_sd),
        "severity_sd": finite_or_none(p.severity_sd),
        "runs_confirming": int(p.runs_confirming), "first_seen": iso_time(p.first_seen),
        "last_confirmed": iso_time(p.last_confirmed), "first_run_id": p.first_run_id, "last_run_id": p.last_run_id,
        "active": bool(p.active), "listed": bool(p.listed), "confirmed": bool(p.listed), "tendency": p.tendency,
        "rate_per_year": finite_or_none(p.rate_per_year), "rate_low": finite_or_none(p.rate_low),
        "rate_high": finite_or_none(p.rate_high), "rate_unit": "ln units per year",
        "amplitude_percent_per_year": amplitude_percent_per_year(1 if p.direction > 0 else -1, p.rate_per_year),
        **_amplitude_interval(1 if p.direction > 0 else -1, p.rate_low, p.rate_high),
        **_outlook(p, nxt),
        "status": p.status, "status_comment": p.status_comment, "status_by": p.status_by,
        "status_at": iso_time(p.status_at),
        "actions": [action_dict(a) for a in actions], "explained_by": p.explained_by,
        "assets": list(assets), "muted": muted_reason is not None, "muted_reason": muted_reason,
        "method_version": p.method_version,
    }
