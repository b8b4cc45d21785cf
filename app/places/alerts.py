"""The alerts of places: a new place on the work list, a tier change, a place back (found again after it
was inactive or marked fixed) — one outbox row per active webhook per run with such events, written in
the publish transaction and sent by the workers' delivery loop like the flags' alerts
(:mod:`app.condition.alerts`). A run that changes nothing on the work list raises none."""

from __future__ import annotations

from collections.abc import Sequence

from sqlalchemy.orm import Session

from app.core.jsonable import iso_time
from app.db.models import ConditionLine, Place, PlaceEventRow, Run
from app.db.webhooks import EVENT_PLACES, enqueue
from app.places.answers import place_dict, tier_name

__all__ = ["EVENT_PLACES", "ALERTED_KINDS", "enqueue_place_events"]

#: Event kinds an alert is sent for.
ALERTED_KINDS: tuple[str, ...] = ("new", "tier_up", "tier_down", "back")


def enqueue_place_events(session: Session, run_id: int, line: ConditionLine,
                         events: Sequence[PlaceEventRow]) -> list[int]:
    """Deliveries of a run's place alerts to every active webhook (none without such events); their ids.

    The payload carries each event with its place as the API answers it (id, status, tier, extent …).
    """
    alerted = [e for e in events if e.alerted and e.kind in ALERTED_KINDS]
    if not alerted:
        return []
    run = session.get(Run, run_id)
    items = []
    for e in alerted:
        place = session.get(Place, e.place_id)
        items.append({"kind": e.kind, "place_id": e.place_id, "old_tier": tier_name(e.old_tier),
                      "new_tier": tier_name(e.new_tier), "place": place_dict(place, line)})
    payload = {"event": EVENT_PLACES, "run_id": run_id, "line_id": line.line_id, "track": line.track,
               "start_time": iso_time(run.start_time or run.created_at) if run is not None else None,
               "n_events": len(items), "events": items}
    return enqueue(session, EVENT_PLACES, payload, run_id=run_id)
