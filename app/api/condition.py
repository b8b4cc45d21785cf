"""Track condition over time, from the segment condition store (never the 25 cm rows).

``GET /condition/lines`` — the lines and tracks of the store;
``GET /condition/heatmap`` — index per run × segment, flagged cells marked;
``GET /condition/trend`` — one segment over every run, with maintenance actions;
``GET /condition/changes`` and ``GET /condition/runs/{id}/changes`` — the change
list (flags) of a line's newest run or of any run; ``GET /condition/flags`` — the
feed of flags for data systems, ``since=`` the last id seen. ``GET /condition/hotspots``
(``.csv``, ``.geojson``), the retired hotspot work list, answers 410 naming ``/condition/places``
(the work list: :mod:`app.api.places`; kept for one release).

A line id (and track) without runs in the store answers 404 naming
``line_id``; a km outside the stored extent of the line answers 422 naming the
km parameter; ``segment_m`` is one of the store's segment lengths (10 or 100 m).
Each route checks its query and calls one function of :mod:`app.condition.answers`.
"""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Query

from app.analysis.condition import FINE_SEGMENT_M, OVERVIEW_SEGMENT_M, SEGMENT_LENGTHS_M
from app.api.deps import (
    DbDep,
    RunId,
    SettingsDep,
    WheelQ,
    check_km,
    km_query,
    parse_time_range,
    wheel_param,
)
from app.api.errors import ApiError
from app.api.schemas.condition import (
    ChangesOut,
    ConditionLinesOut,
    FlagFeedOut,
    HeatmapOut,
    TrendOut,
)
from app.condition import answers
from app.core.i18n import _

__all__ = ["router", "segment_length", "LineIdQ", "TrackQ"]

router = APIRouter(prefix="/condition", tags=["condition"])

LineIdQ = Annotated[str, Query(min_length=1, max_length=128, description="Line id")]
TrackQ = Annotated[str | None, Query(max_length=64, description="Track (default: the line's only track)")]
SegmentQ = Annotated[int, Query(description="segment length, m: " + " or ".join(f"{s:g}" for s in SEGMENT_LENGTHS_M))]
#: Default segment of the heat map (the overview rows) and of a trend or the work list (the finest), m.
_OVERVIEW_M, _FINE_M = int(OVERVIEW_SEGMENT_M), int(FINE_SEGMENT_M)
_MAX_FEED = 1000


def segment_length(value: int) -> int:
    """``segment_m`` checked: one of the store's segment lengths (422 otherwise)."""
    if value not in SEGMENT_LENGTHS_M:
        raise ApiError(422, "segment_m", _("must be {choices}, got {value}", choices=' or '.join(f'{s:g}' for s in SEGMENT_LENGTHS_M), value=value))
    return value


@router.get("/lines", response_model=ConditionLinesOut, summary="Lines and tracks of the condition store")
def lines(db: DbDep) -> dict:
    return answers.lines(db)


@router.get("/heatmap", response_model=HeatmapOut, summary="Index per run × segment of a line")
def heatmap(db: DbDep, line_id: LineIdQ, track: TrackQ = None, segment_m: SegmentQ = _OVERVIEW_M, wheel: WheelQ = None,
            km_from: Annotated[float | None, km_query("Lower km bound")] = None,
            km_to: Annotated[float | None, km_query("Upper km bound")] = None,
            date_from: Annotated[str | None, Query(description="ISO date or datetime")] = None,
            date_to: Annotated[str | None, Query(description="ISO date or datetime")] = None) -> dict:
    """Rows are the line's runs (oldest first), columns its segments; the index of the wheel
    asked for, or the mean over the wheels. ``flagged`` marks cells holding a flag of the run."""
    seg_m = segment_length(segment_m)
    w = wheel_param(wheel)
    check_km(km_from, km_to)
    start, end = parse_time_range(date_from, date_to, ("date_from", "date_to"), whole_days=True)
    return answers.heatmap(db, line_id, track, segment_m=seg_m, wheel=w, km_from=km_from, km_to=km_to,
                           date_from=start, date_to=end)


@router.get("/trend", response_model=TrendOut, summary="One segment over every run of a line")
def trend(db: DbDep, settings: SettingsDep, line_id: LineIdQ, km: Annotated[float, km_query("A km inside the segment")],
          track: TrackQ = None, segment_m: SegmentQ = _FINE_M, wheel: WheelQ = None) -> dict:
    """Per run (oldest first) the segment's condition index (mean over the wheels), the same relative
    to the surrounding track of the run (within ``TRACKVKF_PLACES_EFFECT_AROUND_M`` of it, the segment
    widened by ``…_MARGIN_M`` left out: what the run's speed and level share cancels) and each wheel's
    row, with the maintenance actions that cover the segment."""
    seg_m = segment_length(segment_m)
    return answers.trend(db, line_id, track, km=km, segment_m=seg_m, wheel=wheel_param(wheel),
                         around_m=settings.places_effect_around_m, margin_m=settings.places_effect_margin_m)


@router.get("/changes", response_model=ChangesOut, summary="Change list of a line's newest run")
def newest_changes(db: DbDep, line_id: LineIdQ, track: TrackQ = None) -> dict:
    """The flags of the line's newest run in the store, strongest first."""
    return answers.newest_changes(db, line_id, track)


@router.get("/runs/{run_id}/changes", response_model=ChangesOut, summary="Change list of a run")
def run_changes(db: DbDep, run_id: RunId) -> dict:
    """The flags of a run, strongest first; 404 when the run has no rows in the store."""
    return answers.run_changes(db, run_id)


@router.get("/flags", response_model=FlagFeedOut, summary="Feed of condition flags (poll with since=)")
def flags(db: DbDep, since: Annotated[int, Query(ge=0, le=2**62, description="last flag id seen (0: from the start)")] = 0,
          limit: Annotated[int, Query(ge=1, le=_MAX_FEED)] = 200, line_id: str | None = None, track: TrackQ = None,
          new_only: Annotated[bool, Query(description="only flags new in their run")] = False) -> dict:
    """Flags with an id above ``since``, ascending. Ids grow in the order the flags become
    visible, so a system that keeps the last id it saw (``next_since``) never misses one; the
    flags of a reprocessed run are replaced (new ids)."""
    return answers.flags(db, since=since, limit=limit, line_id=line_id, track=track, new_only=new_only)


# --- the old hotspot work list: gone, pointing at the places ---------------------------------
#: Where the work list is now (docs/places.md).
PLACES_PATH = "/api/v1/condition/places"


@router.get("/hotspots", include_in_schema=False)
@router.get("/hotspots.csv", include_in_schema=False)
@router.get("/hotspots.geojson", include_in_schema=False)
def hotspots_gone() -> None:
    """The hotspot work list was retired: 410 naming the places (the work list since issue 25)."""
    raise ApiError(410, "path", _("the hotspot work list was retired: use {path} (.csv, .geojson)", path=PLACES_PATH),
                   headers={"Link": f'<{PLACES_PATH}>; rel="alternate"'})
