"""The service's clock (app/core/clock.py): the system's by default, an installed one while in use."""

from __future__ import annotations

import datetime as dt

import pytest

from app.core import clock as clock_module
from app.core.clock import OffsetClock, SystemClock, clock_in_use, current_clock, use_clock, utcnow
from app.db.models import utcnow as stored_rows_now


def test_the_system_clock_is_used_unless_another_is_installed() -> None:
    assert isinstance(current_clock(), SystemClock)
    before = dt.datetime.now(dt.UTC)
    now = utcnow()
    assert now.tzinfo is not None and now.utcoffset() == dt.timedelta(0)
    assert before <= now <= dt.datetime.now(dt.UTC)
    assert stored_rows_now is clock_module.utcnow  # the stored rows' "now" is the service's clock


def test_an_offset_clock_moves_on_by_what_is_added_and_time_still_runs() -> None:
    c = OffsetClock()
    with clock_in_use(c):
        first = utcnow()
        assert c.advance(3600.0) - first >= dt.timedelta(hours=1)
        assert c.offset_s == 3600.0
        later = stored_rows_now()
        assert later - dt.datetime.now(dt.UTC) > dt.timedelta(minutes=59)
        assert utcnow() >= later  # never backwards
    assert isinstance(current_clock(), SystemClock)
    assert abs(utcnow() - dt.datetime.now(dt.UTC)) < dt.timedelta(minutes=1)


def test_bad_arguments_are_refused() -> None:
    c = OffsetClock()
    for bad in (-1.0, float("nan"), float("inf"), "5"):
        with pytest.raises(ValueError, match="seconds"):
            c.advance(bad)  # type: ignore[arg-type]
    with pytest.raises(TypeError, match="now"):
        use_clock(object())  # type: ignore[arg-type]
    assert use_clock(None) is current_clock()
