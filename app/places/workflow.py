"""The engineers' workflow of a place: open → acknowledged → planned → fixed or false alarm.

Any status can be set from any other (an engineer corrects a mistake the same way), always with a
comment; each change is kept in the place's status history (who, when, old, new, comment) and in the
audit log (``place.status``), in one transaction. The service sets statuses itself in two cases
(:mod:`app.places.store`, recorded by ``trackvkf``): a maintenance action that repaired a place
marks it ``fixed``; a place marked ``fixed`` that a later run finds again is reopened (``open``,
event ``back``) with its history.
"""

from __future__ import annotations

from app.audit import record
from app.core.errors import ApiError, not_found
from app.core.i18n import _
from app.core.security import Actor
from app.db import places as q
from app.db.models import PLACE_STATUSES, ConditionLine, Place, PlaceStatusChange, utcnow
from app.db.session import Database
from app.places.answers import place_dict

__all__ = ["MAX_COMMENT_CHARS", "PLACE_STATUSES", "set_status"]

#: Longest status comment, characters.
MAX_COMMENT_CHARS = 2000


def set_status(db: Database, place_id: int, status: str, comment: str, actor: Actor) -> dict:
    """Set a place's status with a comment; the place as answered.

    Raises
    ------
    ApiError
        422 naming ``status`` (unknown) or ``comment`` (empty or too long); 404 naming ``place_id``.
    """
    if status not in PLACE_STATUSES:
        raise ApiError(422, "status", _("unknown status {status}; one of {choices}", status=repr(status),
                                                  choices=', '.join(PLACE_STATUSES)))
    text = (comment or "").strip()
    if not text:
        raise ApiError(422, "comment", _("a status change needs a comment (what was decided and why)"))
    if len(text) > MAX_COMMENT_CHARS:
        raise ApiError(422, "comment", _("at most {max} characters, got {n}", max=MAX_COMMENT_CHARS, n=len(text)))
    with db.write() as session:
        p = session.get(Place, place_id, with_for_update=True)
        if p is None:
            raise not_found("place", place_id)
        old, now = p.status, utcnow()
        session.add(PlaceStatusChange(place_id=p.id, by=actor.name, at=now, old=old, new=status, comment=text))
        p.status, p.status_comment, p.status_by, p.status_at = status, text, actor.name, now
        record(session, actor, "place.status", target=p.id,
               detail={"old": old, "new": status, "comment": text})
        session.flush()
        line = session.get(ConditionLine, p.line_key)
        return place_dict(p, line, q.actions_of(session, [p.id])[p.id])
