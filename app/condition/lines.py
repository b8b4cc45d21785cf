"""A line of the condition store as a request names it (line id, optional track), and its km extent."""

from __future__ import annotations

import math

from app.condition import readers as reader
from app.core.errors import ApiError
from app.core.i18n import _
from app.db.models import ConditionLine
from app.db.session import Database

__all__ = ["resolve_line", "check_line_km"]


def resolve_line(db: Database, line_id: str, track: str | None) -> ConditionLine:
    """The store's line; 404 naming ``line_id`` when it has no runs there, 422 when the track is ambiguous."""
    with db.read() as session:
        found = reader.find_lines(session, line_id, track)
    if not found:
        raise ApiError(404, "line_id", _("line {line} track {track} has no runs in the condition store",
                                         line=repr(line_id), track=repr(track)) if track is not None
                       else _("line {line} has no runs in the condition store", line=repr(line_id)))
    if len(found) > 1:
        raise ApiError(422, "track", _("line {line} has tracks {tracks}: choose one", line=repr(line_id),
                                              tracks=', '.join(repr(x.track) for x in found)))
    return found[0]


def check_line_km(line: ConditionLine, **values: float | None) -> None:
    """422 naming the parameter when a km lies outside the line's stored extent."""
    if line.km_min is None or line.km_max is None:
        return
    for name, value in values.items():
        if value is None:
            continue
        if not math.isfinite(value) or value < line.km_min - 1e-9 or value > line.km_max + 1e-9:
            raise ApiError(422, name, _("km {value} is outside line {line} track {track} (km {km_min:.3f}–{km_max:.3f})",
                                        value=value, line=repr(line.line_id), track=repr(line.track),
                                        km_min=line.km_min, km_max=line.km_max))
