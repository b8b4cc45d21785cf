"""The query and path parameters the routes share, and their checks (422 naming the parameter).

Ids (:data:`RunId`, :data:`JobId`), page offsets and sizes, km bounds
(:func:`km_query`, :func:`check_km`), ISO 8601 times (:func:`parse_time_range`) and the
wheel (:data:`WheelQ` with :func:`wheel_param`: ``"11"`` … ``"42"``, ``"Z11"`` accepted).
"""

from __future__ import annotations

import datetime as dt
import math
from typing import Annotated, Any, Literal

from fastapi import Path, Query

from app.core.errors import ApiError
from app.core.i18n import _
from app.core.ids import MAX_ID
from app.io import WHEELS
from app.settings import Settings

__all__ = [
    "RunId",
    "JobId",
    "IdQuery",
    "PageOffset",
    "KM_BOUND",
    "km_query",
    "check_km",
    "check_page_size",
    "parse_time",
    "parse_time_range",
    "WHEEL_PATTERN",
    "Wheel",
    "WheelQ",
    "wheel_param",
]

RunId = Annotated[int, Path(ge=1, le=MAX_ID, description="Run id")]
JobId = Annotated[int, Path(ge=1, le=MAX_ID, description="Job id")]
#: An optional id in the query string (``?reference_run_id=``), bounded like the path ids.
IdQuery = Annotated[int | None, Query(ge=1, le=MAX_ID)]
PageOffset = Annotated[int, Query(ge=0, le=10**9)]


#: Largest |km| a query accepts.
KM_BOUND = 100_000.0


def km_query(description: str | None = None) -> Any:
    """The ``Query`` of a km parameter: within ±:data:`KM_BOUND`.

    Use as ``Annotated[float | None, km_query("Lower km bound")]``.
    """
    return Query(ge=-KM_BOUND, le=KM_BOUND, description=description)


def check_km(km_from: float | None, km_to: float | None) -> None:
    """422 unless the km bounds are finite and ordered."""
    for name, value in (("km_from", km_from), ("km_to", km_to)):
        if value is not None and not math.isfinite(value):
            raise ApiError(422, name, _("must be a finite number"))
    if km_from is not None and km_to is not None and km_from > km_to:
        raise ApiError(422, "km_from", _("({km_from}) is greater than km_to ({km_to})", km_from=km_from, km_to=km_to))


def check_page_size(limit: int, settings: Settings) -> None:
    """422 for a page larger than ``settings.max_page_size``."""
    if limit > settings.max_page_size:
        raise ApiError(422, "limit", _("must be <= {max_page_size}", max_page_size=settings.max_page_size))


def parse_time(
    value: str | None, name: str, *, day: Literal["start", "end"] | None = None
) -> dt.datetime | None:
    """An ISO 8601 date or datetime query parameter as an aware UTC datetime.

    Parameters
    ----------
    value : str or None
        The parameter; None or ``""`` give None. A datetime without offset is UTC.
    name : str
        Its name, for the 422 message.
    day : {"start", "end"}, optional
        What a bare date (``YYYY-MM-DD``) means: the first or the last instant
        of that day (UTC). Without it a date is read as a datetime (midnight).

    Raises
    ------
    ApiError
        422 for a value that is not ISO 8601 or out of the representable range.
    """
    if value is None or value == "":
        return None
    try:
        if day is not None and len(value) == 10:
            t = dt.time.max if day == "end" else dt.time.min
            return dt.datetime.combine(dt.date.fromisoformat(value), t, tzinfo=dt.UTC)
        parsed = dt.datetime.fromisoformat(value.replace("Z", "+00:00"))
    except ValueError:
        raise ApiError(422, name, _("not an ISO 8601 date or datetime: {value}", value=repr(value))) from None
    if parsed.tzinfo is None:
        parsed = parsed.replace(tzinfo=dt.UTC)
    try:
        return parsed.astimezone(dt.UTC)
    except OverflowError:
        raise ApiError(422, name, _("out of the representable range: {value}", value=repr(value))) from None


def parse_time_range(
    since: str | None, until: str | None, names: tuple[str, str], *, whole_days: bool = False
) -> tuple[dt.datetime | None, dt.datetime | None]:
    """Both ends of a time filter (:func:`parse_time`); 422 on the first name if they are reversed.

    With ``whole_days`` a bare date as ``since`` starts at the beginning of the
    day and one as ``until`` ends at its end.
    """
    start = parse_time(since, names[0], day="start" if whole_days else None)
    end = parse_time(until, names[1], day="end" if whole_days else None)
    if start and end and start > end:
        raise ApiError(422, names[0], _("is after {other}", other=names[1]))
    return start, end


#: What a wheel parameter may look like before :func:`wheel_param` checks it (short, no odd characters).
WHEEL_PATTERN = r"^[0-9A-Za-z]{1,8}$"
#: An optional wheel (None: every wheel, or their mean); pass it through :func:`wheel_param`.
WheelQ = Annotated[str | None, Query(pattern=WHEEL_PATTERN, description="wheel: 11, 12, 41 or 42 (or Z11 …)")]
#: A wheel that must be given (or has a default); pass it through :func:`wheel_param`.
Wheel = Annotated[str, Query(pattern=WHEEL_PATTERN, description="wheel: 11, 12, 41 or 42 (or Z11 …)")]


def wheel_param(value: str | None) -> str | None:
    """A wheel parameter as the wheel's name (``"Z11"`` → ``"11"``); 422 naming ``wheel`` for
    anything but a wheel of the service (:data:`app.io.WHEELS`); None stays None."""
    if value is None:
        return None
    w = value[1:] if value[:1] in ("Z", "z") else value
    if w not in WHEELS:
        raise ApiError(422, "wheel", _("must be one of {choices} (or Z11 …), got {w}", choices=', '.join(WHEELS), w=repr(w)))
    return w
