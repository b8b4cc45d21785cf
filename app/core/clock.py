"""The service's clock: the current time (aware UTC) of every stored timestamp, due time and back-off.

Every "now" of the service comes from :func:`utcnow` (``app.db.models.utcnow`` is this function):
when a row was written, when a delivery, a job or a places follow-up is due again, until when a
rotated secret still signs. It reads the process's current :class:`Clock`, the :class:`SystemClock`
unless :func:`use_clock` installed another one. An :class:`OffsetClock` is the system's time moved
on by what :meth:`OffsetClock.advance` added: a back-off of minutes passes at once (the tests wait
out retries so), and time still runs between two calls, so rows keep their order.
"""

from __future__ import annotations

import datetime as dt
import math
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Protocol

__all__ = ["Clock", "SystemClock", "OffsetClock", "utcnow", "current_clock", "use_clock", "clock_in_use"]


class Clock(Protocol):
    """What tells the time: :meth:`now`, an aware datetime in UTC."""

    def now(self) -> dt.datetime: ...


class SystemClock:
    """The system's time."""

    def now(self) -> dt.datetime:
        """Current time, timezone-aware UTC."""
        return dt.datetime.now(dt.UTC)


class OffsetClock:
    """The system's time plus an offset that :meth:`advance` increases (never decreases)."""

    def __init__(self) -> None:
        self._offset = dt.timedelta(0)
        self._lock = threading.Lock()

    @property
    def offset_s(self) -> float:
        """Seconds this clock is ahead of the system's, s."""
        return self._offset.total_seconds()

    def advance(self, seconds: float) -> dt.datetime:
        """Move the clock on by ``seconds`` (>= 0, finite); returns the new current time."""
        if not (isinstance(seconds, int | float) and math.isfinite(seconds) and seconds >= 0):
            raise ValueError(f"seconds must be a finite number >= 0, got {seconds!r}")
        with self._lock:
            self._offset += dt.timedelta(seconds=float(seconds))
        return self.now()

    def now(self) -> dt.datetime:
        """The system's time plus the offset, timezone-aware UTC."""
        return dt.datetime.now(dt.UTC) + self._offset


_SYSTEM = SystemClock()
_current: Clock = _SYSTEM


def utcnow() -> dt.datetime:
    """Current time of the process's clock, timezone-aware UTC."""
    return _current.now()


def current_clock() -> Clock:
    """The clock :func:`utcnow` reads."""
    return _current


def use_clock(clock: Clock | None) -> Clock:
    """Make ``clock`` the process's clock (``None``: the system's); returns the previous one."""
    global _current
    if clock is not None and not callable(getattr(clock, "now", None)):
        raise TypeError(f"clock must have a now() method, got {clock!r}")
    previous, _current = _current, clock or _SYSTEM
    return previous


@contextmanager
def clock_in_use(clock: Clock) -> Iterator[Clock]:
    """Use ``clock`` within the ``with`` block, then the previous clock again."""
    previous = use_clock(clock)
    try:
        yield clock
    finally:
        use_clock(previous)
