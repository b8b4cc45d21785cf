"""The alerts of new condition flags: one outbox row per active webhook, written in the publish
transaction (so an alert exists exactly when its flags do) and sent by the workers' delivery
loop (:mod:`worker.deliveries`) after the commit, never in the way of processing.

The payload is the run, its line and the new flags as the API answers them
(:func:`app.condition.readers.flag_dict`), with ``feed_since``: the ``since=`` of
``GET /condition/flags`` that lists the same flags.
"""

from __future__ import annotations

from collections.abc import Sequence

from sqlalchemy.orm import Session

from app.condition.readers import flag_dict
from app.core.jsonable import iso_time
from app.db.models import ConditionFlag, ConditionLine, Run
from app.db.webhooks import EVENT_FLAGS, enqueue

__all__ = ["EVENT_FLAGS", "enqueue_new_flags"]


def enqueue_new_flags(session: Session, run_id: int, line: ConditionLine,
                      flags: Sequence[ConditionFlag]) -> list[int]:
    """Deliveries of a published run's new flags to every active webhook (none without new flags); their ids."""
    new = [f for f in flags if f.is_new]
    if not new:
        return []
    run = session.get(Run, run_id)
    payload = {
        "event": EVENT_FLAGS, "run_id": run_id, "line_id": line.line_id, "track": line.track,
        "start_time": iso_time(run.start_time or run.created_at) if run is not None else None,
        "n_flags": len(new), "flags": [flag_dict(f, line) for f in new],
        "feed_since": min(f.id for f in new) - 1,
    }
    return enqueue(session, EVENT_FLAGS, payload, run_id=run_id)
