"""What the planning report shows, read through the services that answer the Condition page:
the section classes in the railway's scheme (:func:`app.places.sections.line_sections`), the
work list (:func:`app.places.worklist.list_places`), the line's rail findings — welds and joints
the runs found, listed apart from the places, never ranked with them
(:func:`app.condition.rail_findings.line_findings`) —, each open place's history with the
maintenance over it (:func:`app.places.worklist.place_history`), the maintenance effects
(:func:`app.places.effect.action_effects`) and the line's geometry (the map).
"""

from __future__ import annotations

import datetime as dt
from dataclasses import dataclass, field
from typing import Any

from app.condition.lines import resolve_line
from app.condition.rail_findings import line_findings
from app.db import recorder_crud
from app.db.session import Database
from app.io.geometry import LineGeometry
from app.places.config import PlacesConfig
from app.places.effect import action_effects
from app.places.passes import place_passes
from app.places.sections import line_sections
from app.places.worklist import PlaceQuery, list_places, place_history

__all__ = ["ReportData", "MAX_PLACES", "gather"]

#: most places given a sheet of their own (the rest stay in the work list)
MAX_PLACES = 200
#: the maintenance effects' windows (as the Condition page asks for them), days, and regained fraction
EFFECT_BEFORE_DAYS, EFFECT_AFTER_DAYS, EFFECT_REGAIN = 90.0, 30.0, 0.5


@dataclass(frozen=True)
class ReportData:
    """Everything one report shows (answers of the services, as the API gives them)."""

    line_id: str
    track: str
    date: dt.date
    sections: dict[str, Any]
    places: list[dict[str, Any]]
    total_places: int
    histories: dict[int, dict[str, Any]]
    effects: list[dict[str, Any]]
    geometry: LineGeometry | None
    km_range: tuple[float, float]
    #: the line's steady rail findings (``GET /condition/rail-findings?steady=true``'s items: km, type, dip
    #: depth in mm, runs seen of runs passed, the depth's trend in mm a year), ascending km
    rail_findings: list[dict[str, Any]] = field(default_factory=list)
    #: the findings left out: seen by fewer than half the runs that passed them
    rail_unsteady: int = 0
    #: the passes of the places found by their trend, by place id (``GET /condition/places/{id}/passes``: the
    #: matched passes their trend is fitted on, and the trend): their own observations are the few runs since
    passes: dict[int, dict[str, Any]] = field(default_factory=dict)


def gather(db: Database, settings: Any, line_id: str, track: str | None, *, date: dt.date,
           lang: str = "en") -> ReportData:
    """Read what the report of a line and track shows (404 naming ``line_id`` without runs,
    422 naming ``track`` when it is ambiguous)."""
    line = resolve_line(db, line_id, track)
    config = PlacesConfig.from_settings(settings)
    sections = line_sections(db, settings, line.line_id, line.track, lang=lang)
    listed = list_places(db, PlaceQuery(line_id=line.line_id, track=line.track, limit=MAX_PLACES), config)
    places = listed["items"]
    histories = {p["id"]: place_history(db, p["id"], config) for p in places}
    passes = {p["id"]: place_passes(db, p["id"], config) for p in places if "trend" in p["evidence"]}
    rails = line_findings(db, line.line_id, line.track, steady_only=True)
    effects = action_effects(db, line.line_id, line.track, types=None, since=None, km_from=None, km_to=None,
                             before_days=EFFECT_BEFORE_DAYS, after_days=EFFECT_AFTER_DAYS,
                             regain_fraction=EFFECT_REGAIN, config=config)["items"]
    with db.read() as session:
        row = recorder_crud.find_geometry(session, line.line_id, line.track)
        geometry = recorder_crud.to_line_geometry(row) if row is not None else None
    kms = [(s["km_from"], s["km_to"]) for s in sections["sections"]]
    kms += [(p["km_from"], p["km_to"]) for p in places]
    km_range = (min(a for a, _ in kms), max(b for _, b in kms)) if kms else (0.0, 1.0)
    return ReportData(line_id=line.line_id, track=line.track, date=date, sections=sections, places=places,
                      total_places=int(listed["total"]), histories=histories, effects=effects, geometry=geometry,
                      km_range=km_range, rail_findings=rails["items"], rail_unsteady=int(rails["unsteady"]),
                      passes=passes)
