"""The work list of places (issue 25, docs/places.md): places with severity, identity and history.

``GET /condition/places`` (``.csv``, ``.geojson``) — the listed places ranked by tier, then days to the
next tier, then severity; ``GET /condition/places/events`` — the feed of place events (``since=``);
``GET /condition/places/{id}`` — a place with its observations, events,
status history and maintenance; ``GET /condition/places/{id}/passes`` — the segment it is read at run by run,
its matched passes marked; ``PATCH /condition/places/{id}/status`` — an engineer sets its
workflow status with a comment (audited). Every value is the speed-conditioned stiffness index
``ln(A / A_ref(class, v))``. Routes parse, authorise and call one function of :mod:`app.places`.
"""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Depends, Path, Query
from fastapi.responses import JSONResponse, Response
from pydantic import BaseModel, Field

from app.api.csv_header import CsvLanguage
from app.api.deps import DbDep, EngineerActor, SettingsDep
from app.api.schemas.text import Text
from app.core.ids import MAX_ID
from app.places import passes, workflow, worklist
from app.places.config import PlacesConfig
from app.places.worklist import PlaceQuery

__all__ = ["router"]

router = APIRouter(prefix="/condition", tags=["places"])

PlaceId = Annotated[int, Path(ge=1, le=MAX_ID, description="Place id (stable across runs)")]


def _query(
    line_id: Annotated[str | None, Query(min_length=1, max_length=128, description="Line id (default: all)")] = None,
    track: Annotated[str | None, Query(min_length=1, max_length=64, description="Track (needs line_id)")] = None,
    tier: Annotated[list[str] | None, Query(description="Tier(s): watch, alert, intervention, immediate")] = None,
    status: Annotated[list[str] | None, Query(description="Status(es): open, acknowledged, planned, fixed, "
                                                          "false_alarm")] = None,
    include_closed: Annotated[bool, Query(description="Also inactive, fixed and false-alarm places")] = False,
    limit: Annotated[int, Query(ge=1, le=1000)] = 100,
    offset: Annotated[int, Query(ge=0, le=10**7)] = 0,
) -> PlaceQuery:
    return PlaceQuery(line_id=line_id, track=track, tiers=tuple(tier or ()), statuses=tuple(status or ()),
                      include_closed=include_closed, limit=limit, offset=offset).checked()


PlaceQ = Annotated[PlaceQuery, Depends(_query)]


class StatusIn(BaseModel):
    """A status change: the new status and why."""

    status: Text = Field(min_length=1, max_length=32, description="open, acknowledged, planned, fixed, false_alarm")
    comment: Text = Field(min_length=1, max_length=workflow.MAX_COMMENT_CHARS,
                         description="What was decided and why (required)")


@router.get("/places", summary="Work list: places ranked by tier, time to the next tier, severity")
def places(db: DbDep, settings: SettingsDep, q: PlaceQ) -> dict:
    """Listed places (active open ones; a ``status`` filter: those statuses, open ones while active;
    ``include_closed``: also inactive and closed ones), each with its
    extent, peak, tier and action, evidence, wheels, runs, trend and time to the next tier, status."""
    return worklist.list_places(db, q, PlacesConfig.from_settings(settings))


@router.get("/places.csv", summary="Work list as CSV (the filters of /condition/places)",
            response_class=Response, responses={200: {"content": {"text/csv": {}}}})
def places_csv(db: DbDep, settings: SettingsDep, q: PlaceQ, lang: CsvLanguage) -> Response:
    """One row per place of the page; ``X-Total-Count``: the places the filters match, ``X-Omitted-Count``:
    how many of them the page (``offset``, ``limit``) leaves out; ``header=labels``: the header in the
    user's language."""
    text, total, omitted = worklist.places_csv(db, q, PlacesConfig.from_settings(settings), lang)
    return Response(text, media_type="text/csv",
                    headers={"Content-Disposition": 'attachment; filename="places.csv"',
                             "X-Total-Count": str(total), "X-Omitted-Count": str(omitted)})


@router.get("/places.geojson", summary="Work list as GeoJSON (the filters of /condition/places)",
            response_class=JSONResponse, responses={200: {"content": {"application/geo+json": {}}}})
def places_geojson(db: DbDep, settings: SettingsDep, q: PlaceQ) -> JSONResponse:
    """One feature per place: its extent as a LineString where the line's geometry is imported, else null."""
    return JSONResponse(worklist.places_geojson(db, q, PlacesConfig.from_settings(settings)), media_type="application/geo+json")


@router.get("/places/events", summary="Feed of place events (poll with since=)")
def place_events(db: DbDep, settings: SettingsDep,
                 since: Annotated[int, Query(ge=0, le=2**62, description="last event id seen (0: from the start)")] = 0,
                 limit: Annotated[int, Query(ge=1, le=1000)] = 200,
                 every: Annotated[bool, Query(description="every event, not only the alerted ones")] = False) -> dict:
    """New places, tier changes and places back (``every``: also repaired, linked, inactive), oldest
    first, each with its place (id, status, tier …); ``next_since`` for the next poll."""
    return worklist.event_feed(db, since, limit, alerted_only=not every, config=PlacesConfig.from_settings(settings))


@router.get("/places/{place_id}", summary="A place with its history")
def place(db: DbDep, settings: SettingsDep, place_id: PlaceId) -> dict:
    """The place, its observations run by run, its events, status history and the maintenance over it."""
    return worklist.place_history(db, place_id, PlacesConfig.from_settings(settings))


@router.get("/places/{place_id}/passes", summary="A place's segment run by run: its matched passes")
def place_passes(db: DbDep, settings: SettingsDep, place_id: PlaceId) -> dict:
    """The index at the 10 m segment the place is read at (its peak; for a place found by its trend where it
    grows fastest) in its newest run and in the earlier runs, each marked
    whether it passed at a matched speed with the same vehicle (what the place's change and trend are read
    against); for a place found by its trend, the line fitted through those passes."""
    return passes.place_passes(db, place_id, PlacesConfig.from_settings(settings))


@router.patch("/places/{place_id}/status", summary="Set a place's workflow status (with a comment)")
def place_status(db: DbDep, place_id: PlaceId, body: StatusIn, actor: EngineerActor) -> dict:
    """open → acknowledged → planned → fixed / false_alarm; every change recorded (who, when, old, new,
    comment) and audited."""
    return workflow.set_status(db, place_id, body.status, body.comment, actor)
