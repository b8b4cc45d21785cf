"""The work list of places, its exports and a place's history (the readers of :mod:`app.places`).

The list holds the **listed** places that are not a maintenance action's effect, and the **new** ones
the newest run that covered them found and the lifecycle has not confirmed yet (``confirmed: false``:
found by one run, to be confirmed by the next; an engineer learns of a new change from the run that
finds it, the alerts still wait for the confirmation); by default only the open ones (active, status
not ``fixed`` / ``false_alarm``); a ``status`` filter lists the places of those statuses, the open ones
among them only while active; ``include_closed`` also the inactive and closed ones. Ranked by
tier (highest first), within a tier the confirmed places before the new ones, then by the days to the
next tier (soonest first; places without a projection after those with one), then by severity (the
magnitude in units of the alert limit that gives the tier), then id — in the database, so a page of a
long list costs one query.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from sqlalchemy import and_, case, func, or_, select
from sqlalchemy.orm import Session

from app.analysis.condition.tiers import TIER_NAMES
from app.assets.labels import label_places
from app.core.csv_export import csv_text
from app.core.errors import ApiError, not_found
from app.core.i18n import _
from app.core.jsonable import iso_time
from app.db import places as q
from app.db import recorder_crud, reference_crud
from app.db.models import PLACE_STATUSES, ConditionLine, Place, PlaceObservation, PlaceRun
from app.db.session import Database
from app.places.answers import QUANTITY, evidence_names, place_dict, tier_name
from app.places.config import DEFAULT_PLACES_CONFIG, PlacesConfig
from app.places.followup import line_places_status

__all__ = ["PlaceQuery", "CLOSED_STATUSES", "list_places", "places_csv", "places_geojson", "place_history",
           "event_feed"]

#: Statuses that take a place off the default list.
CLOSED_STATUSES: tuple[str, ...] = ("fixed", "false_alarm")
#: Columns of the CSV export.
CSV_COLUMNS: tuple[str, ...] = (
    "id", "line_id", "track", "km_from", "km_to", "length_m", "peak", "peak_percent", "peak_km", "direction",
    "reading", "speed_kmh", "tier", "confirmed", "evidence", "wheels", "runs_confirming", "first_seen",
    "last_confirmed", "tendency", "rate_per_year", "rate_low", "rate_high", "amplitude_percent_per_year",
    "amplitude_percent_low", "amplitude_percent_high",
    "next_tier", "projected_date", "days_to_next_tier", "projected_date_early", "projected_date_late",
    "days_to_next_tier_early", "days_to_next_tier_late", "no_projection", "status", "status_comment",
    "status_by", "status_at", "actions", "assets", "active", "muted", "muted_reason", "method_version",
    "peak_sd", "change", "change_sd", "severity", "severity_sd",
)


@dataclass(frozen=True)
class PlaceQuery:
    """Filters and page of the work list (checked by :meth:`checked`)."""

    line_id: str | None = None
    track: str | None = None
    tiers: tuple[str, ...] = ()
    statuses: tuple[str, ...] = ()
    include_closed: bool = False
    limit: int = 100
    offset: int = 0

    def checked(self) -> PlaceQuery:
        """422 naming ``tier`` / ``status`` for an unknown name, ``track`` without ``line_id``."""
        for t in self.tiers:
            if t not in TIER_NAMES:
                raise ApiError(422, "tier", _("unknown tier {tier}; one of {choices}", tier=repr(t), choices=', '.join(TIER_NAMES)))
        for s in self.statuses:
            if s not in PLACE_STATUSES:
                raise ApiError(422, "status", _("unknown status {status}; one of {choices}", status=repr(s), choices=', '.join(PLACE_STATUSES)))
        if self.track is not None and self.line_id is None:
            raise ApiError(422, "track", _("track needs line_id"))
        return self


def _lines(session: Session, qy: PlaceQuery) -> dict[int, ConditionLine]:
    stmt = select(ConditionLine)
    if qy.line_id is not None:
        stmt = stmt.where(ConditionLine.line_id == qy.line_id)
        if qy.track is not None:
            stmt = stmt.where(ConditionLine.track == qy.track)
    lines = {ln.id: ln for ln in session.scalars(stmt)}
    if qy.line_id is not None and not lines:
        raise ApiError(404, "line_id", _("line {line} track {track} has no runs in the condition store",
                                         line=repr(qy.line_id), track=repr(qy.track)) if qy.track
                       else _("line {line} has no runs in the condition store", line=repr(qy.line_id)))
    return lines


#: A place on the list: confirmed by the lifecycle (``listed``), or new — found by the newest run that
#: covered it (no miss since) and not yet confirmed.
ON_LIST = or_(Place.listed.is_(True), and_(Place.active.is_(True), Place.misses == 0))


def _where(qy: PlaceQuery, line_keys: Sequence[int]):
    cond = [ON_LIST, Place.explained_by.is_(None), Place.line_key.in_(list(line_keys))]
    if not qy.include_closed:
        # an open place not seen lately is off the list whatever the statuses asked for (the page always
        # asks for some: it listed them beside its unticked "also places not seen lately"); a closed one
        # is on it when its status is asked for
        cond.append(or_(Place.active.is_(True), Place.status.in_(CLOSED_STATUSES)) if qy.statuses
                    else and_(Place.active.is_(True), Place.status.not_in(CLOSED_STATUSES)))
    if qy.statuses:
        cond.append(Place.status.in_(list(qy.statuses)))
    if qy.tiers:
        cond.append(Place.tier.in_([TIER_NAMES.index(t) for t in qy.tiers]))
    return and_(*cond)


def _ranked(stmt):
    return stmt.order_by(Place.tier.desc(), case((Place.listed.is_(True), 0), else_=1),
                         case((Place.days_to_next.is_(None), 1), else_=0),
                         Place.days_to_next, Place.severity.desc(), Place.id)


def _page(session: Session, qy: PlaceQuery) -> tuple[dict[int, ConditionLine], list[Place], int]:
    lines = _lines(session, qy)
    if not lines:
        return lines, [], 0
    where = _where(qy, list(lines))
    total = int(session.scalar(select(func.count()).select_from(Place).where(where)) or 0)
    rows = list(session.scalars(_ranked(select(Place).where(where)).limit(qy.limit).offset(qy.offset)))
    return lines, rows, total


def labelled(session: Session, lines: dict[int, ConditionLine], rows: list[Place],
             config: PlacesConfig = DEFAULT_PLACES_CONFIG) -> list[dict]:
    """The places as answered: their linked actions, and the known discontinuities on them
    (:func:`app.assets.labels.label_places`: labelled, muted by type, never dropped)."""
    links = q.actions_of(session, [p.id for p in rows])
    labels: dict[int, object] = {}
    by_line: dict[int, list[Place]] = {}
    for p in rows:
        by_line.setdefault(p.line_key, []).append(p)
    for key, ps in by_line.items():
        ln = lines[key]
        got = label_places(session, config.asset_settings(), ln.line_id, ln.track, [p.start_m / 1000.0 for p in ps],
                           [p.end_m / 1000.0 for p in ps])
        labels.update({p.id: lab for p, lab in zip(ps, got, strict=True)})
    speeds = q.latest_speeds(session, [p.id for p in rows])
    out = []
    for p in rows:
        lab = labels.get(p.id)
        item = place_dict(p, lines[p.line_key], links[p.id], assets=lab.assets if lab else (),
                          muted_reason=lab.muted_reason if lab is not None and lab.muted else None,
                          speed_kmh=speeds.get(p.id))
        if lab is not None and lab.assets_more:  # only when capped: the answers of a place on few assets keep their shape
            item["assets_more"] = lab.assets_more
        out.append(item)
    return out


def list_places(db: Database, qy: PlaceQuery, config: PlacesConfig = DEFAULT_PLACES_CONFIG) -> dict:
    """The work list (``GET /condition/places``)."""
    qy = qy.checked()
    with db.read() as session:
        lines, rows, total = _page(session, qy)
        items = labelled(session, lines, rows, config)
        current = [{"line_id": ln.line_id, "track": ln.track, **line_places_status(session, key)}
                   for key, ln in sorted(lines.items())]
    updated = [c["places_updated_at"] for c in current if c["places_updated_at"] is not None]
    # how current the places are: a published run's places follow its publication (app.places.followup)
    return {"line_id": qy.line_id, "quantity": QUANTITY, "items": items, "total": total,
            "places_pending": sum(c["places_pending"] for c in current),
            "places_updated_at": max(updated) if updated else None, "lines": current}


def places_csv(db: Database, qy: PlaceQuery, config: PlacesConfig = DEFAULT_PLACES_CONFIG,
               lang: str | None = None) -> tuple[str, int, int]:
    """The work list as CSV (one row per place; lists joined by ``+``, actions as ``kind date``), written
    by :mod:`app.core.csv_export` (text cells a spreadsheet would run are defused); the header is the
    field names, or given ``lang`` the columns' labels and units in it.

    Returns
    -------
    tuple[str, int, int]
        The CSV text, the number of places the filters match (all pages) and how many of them this page
        leaves out (before ``offset`` and after ``limit``): the route says both in headers.
    """
    answer = list_places(db, qy, config)
    rows = []
    for item in answer["items"]:
        row = dict(item)
        row["evidence"] = "+".join(item["evidence"])
        row["wheels"] = "+".join(item["wheels"])
        row["actions"] = "+".join(f"{a['kind']} {a['date']}" for a in item["actions"])
        row["assets"] = "+".join(f"{a['type']} {a['km']:.3f}" for a in item["assets"])
        rows.append([row.get(c) for c in CSV_COLUMNS])
    total = int(answer["total"])
    return csv_text(CSV_COLUMNS, rows, lang), total, max(0, total - len(rows))


def places_geojson(db: Database, qy: PlaceQuery, config: PlacesConfig = DEFAULT_PLACES_CONFIG) -> dict:
    """The work list as a GeoJSON FeatureCollection: the place's extent as a LineString in WGS84 where
    the line's geometry is imported (else a null geometry), the place's fields as properties."""
    items = list_places(db, qy, config)["items"]
    geoms: dict[tuple[str, str], object] = {}
    with db.read() as session:
        for key in {(i["line_id"], i["track"]) for i in items}:
            row = recorder_crud.find_geometry(session, *key)
            geoms[key] = recorder_crud.to_line_geometry(row) if row is not None else None
    features = []
    for item in items:
        geom = geoms.get((item["line_id"], item["track"]))
        geometry = None
        if geom is not None:
            lon, lat = geom.lonlat_at_km(np.linspace(item["km_from"], item["km_to"], 3))
            geometry = {"type": "LineString",
                        "coordinates": [[float(a), float(b)] for a, b in zip(lon, lat, strict=True)]}
        features.append({"type": "Feature", "id": item["id"], "geometry": geometry, "properties": item})
    return {"type": "FeatureCollection", "features": features}


def place_history(db: Database, place_id: int, config: PlacesConfig = DEFAULT_PLACES_CONFIG) -> dict:
    """A place with its observations, events, status history and the line's maintenance actions over it
    within the time span of the line's runs (``GET /condition/places/{id}``; 404 naming ``place_id``)."""
    with db.read() as session:
        p = session.get(Place, place_id)
        if p is None:
            raise not_found("place", place_id)
        line = session.get(ConditionLine, p.line_key)
        (out,) = labelled(session, {line.id: line}, [p], config)
        obs = session.scalars(select(PlaceObservation).where(PlaceObservation.place_id == p.id)
                              .order_by(PlaceObservation.day, PlaceObservation.id))
        out["observations"] = [
            {"run_id": o.run_id, "run_time": iso_time(o.run_time), "speed_kmh": o.speed_kmh, "level": o.level,
             "level_sd": o.level_sd, "change": o.change, "change_sd": o.change_sd, "tier": TIER_NAMES[int(o.tier)], "km_from": o.start_m / 1000.0,
             "km_to": o.end_m / 1000.0, "peak_km": o.peak_m / 1000.0, "evidence": evidence_names(int(o.evidence)),
             "wheels": [w for w in (o.wheel_labels or "").split(",") if w], "method_version": o.method_version}
            for o in obs]
        out["events"] = [{"kind": e.kind, "run_id": e.run_id, "time": iso_time(e.time),
                          "old_tier": tier_name(e.old_tier), "new_tier": tier_name(e.new_tier),
                          "action_id": e.action_id, "alerted": bool(e.alerted)} for e in q.events_of(session, p.id)]
        out["status_history"] = [{"by": c.by, "at": iso_time(c.at), "old": c.old, "new": c.new,
                                  "comment": c.comment} for c in q.status_history_of(session, p.id)]
        span = session.execute(select(func.min(PlaceRun.run_time), func.max(PlaceRun.run_time))
                               .where(PlaceRun.line_key == p.line_key)).one()
        frame = reference_crud.reference_frame(session, "maintenance", line_id=line.line_id, track=line.track)
    maint = []
    if span[0] is not None:
        lo_d, hi_d = span[0].date(), span[1].date()
        for r in frame.itertuples(index=False):
            a, b = sorted((float(r.km_from), float(r.km_to)))
            if a <= p.end_m / 1000.0 and p.start_m / 1000.0 <= b and lo_d <= r.date <= hi_d:
                maint.append({"id": int(r.id), "kind": str(r.type), "date": r.date.isoformat(), "km_from": a,
                              "km_to": b})
    out["maintenance"] = maint
    return out




def event_feed(db: Database, since: int, limit: int, *, alerted_only: bool = True,
               config: PlacesConfig = DEFAULT_PLACES_CONFIG) -> dict:
    """The feed of place events for data systems (``GET /condition/places/events``): events with an id
    above ``since``, oldest first, each with its place as answered now (id, status, tier …); by default
    the alerted ones (new, tier changes, back). ``next_since``: the ``since=`` of the next poll. Event
    ids become visible in increasing order (the places are updated under one lock, serially)."""
    from app.db.models import PlaceEventRow
    from app.places.alerts import ALERTED_KINDS

    with db.read() as session:
        stmt = select(PlaceEventRow).where(PlaceEventRow.id > since)
        if alerted_only:
            stmt = stmt.where(PlaceEventRow.kind.in_(ALERTED_KINDS))
        events = list(session.scalars(stmt.order_by(PlaceEventRow.id).limit(limit)))
        ids = sorted({e.place_id for e in events})
        rows = {p.id: p for p in session.scalars(select(Place).where(Place.id.in_(ids)))} if ids else {}
        lines = {ln.id: ln for ln in session.scalars(select(ConditionLine).where(
            ConditionLine.id.in_({p.line_key for p in rows.values()})))} if rows else {}
        shaped = {d["id"]: d for d in labelled(session, lines, list(rows.values()), config)}
    items = [{"id": e.id, "kind": e.kind, "place_id": e.place_id, "run_id": e.run_id, "time": iso_time(e.time),
              "old_tier": tier_name(e.old_tier), "new_tier": tier_name(e.new_tier), "action_id": e.action_id,
              "place": shaped.get(e.place_id)} for e in events]
    return {"items": items, "next_since": events[-1].id if events else since}
