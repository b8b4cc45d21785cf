"""Maintenance effect, from the segment condition store: what each imported action did to the
condition index over its extent (before, after, recovery, how long it lasted) and the
before/after view of one action. The index is read against the surrounding track of the
same run (:mod:`app.places.effect`: the one rule of an extent against its surroundings), so runs at
other speeds compare. The paper's
correlation of amplitude with the number of actions stays at ``GET /analytics/maintenance``."""

from __future__ import annotations

import datetime as dt
from typing import Annotated

from fastapi import APIRouter, Path, Query

from app.api.condition import LineIdQ, TrackQ
from app.api.deps import DbDep, SettingsDep, check_km, km_query
from app.api.reference import parse_types
from app.api.schemas.condition import EffectDetailOut, EffectsOut
from app.core.ids import MAX_ID
from app.places.config import PlacesConfig
from app.places.effect import action_effect_detail, action_effects

__all__ = ["router"]

router = APIRouter(prefix="/condition", tags=["condition"])

BeforeQ = Annotated[float, Query(gt=0, le=3650, description="days before the action compared")]
AfterQ = Annotated[float, Query(gt=0, le=3650, description="days just after the action compared")]
RegainQ = Annotated[float, Query(gt=0, le=1, description="fraction of the recovery whose loss ends the effect")]


@router.get("/maintenance-effect", response_model=EffectsOut, summary="Effect of each maintenance action")
def maintenance_effects(
    db: DbDep, settings: SettingsDep, line_id: LineIdQ, track: TrackQ = None,
    type: Annotated[str | None, Query(description="comma-separated action types")] = None,
    since: Annotated[dt.date | None, Query(description="actions on or after this date")] = None,
    km_from: Annotated[float | None, km_query("Lower km bound")] = None,
    km_to: Annotated[float | None, km_query("Upper km bound")] = None,
    before_days: BeforeQ = 90.0, after_days: AfterQ = 30.0, regain_fraction: RegainQ = 0.5,
) -> dict:
    """Every imported action of the line (filtered by type, date, km): the condition index over its
    extent against its surroundings before and after, the recovery, the slope after and how long the recovery lasted."""
    types = parse_types(type)
    check_km(km_from, km_to)
    return action_effects(db, line_id, track, types=types, since=since, km_from=km_from, km_to=km_to,
                          before_days=before_days, after_days=after_days, regain_fraction=regain_fraction,
                          config=PlacesConfig.from_settings(settings))


@router.get("/maintenance-effect/{action_id}", response_model=EffectDetailOut,
            summary="Before/after view of one maintenance action")
def maintenance_effect(
    db: DbDep, settings: SettingsDep, action_id: Annotated[int, Path(ge=1, le=MAX_ID)],
    before_days: BeforeQ = 90.0, after_days: AfterQ = 30.0, regain_fraction: RegainQ = 0.5,
) -> dict:
    """The action's effect, the index over its extent per run, and the index along km (extent
    ± 100 m) averaged over the runs before and the runs just after."""
    return action_effect_detail(db, action_id, before_days=before_days, after_days=after_days,
                                regain_fraction=regain_fraction, config=PlacesConfig.from_settings(settings))
