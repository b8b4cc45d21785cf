"""A developing place keeps the outlook its trend gave it while the runs after do not read it (issue 33: the real
line's developing place, found by its trend, had a time to its next limit on that run and lost it on the next
two, which had no index on its soft segments: its two observations alone are too few for a rate)."""

from __future__ import annotations

import datetime as dt

import numpy as np
from sqlalchemy import select

from app.analysis.condition.lifecycle import Observation, PlaceState
from app.analysis.condition.outlook import linear_trend
from app.analysis.condition.places import EVIDENCE_STEP, EVIDENCE_TREND
from app.db.models import ConditionLine, Place
from app.places.config import DEFAULT_PLACES_CONFIG
from app.places.store import write_run
from tests.db.conftest import db  # noqa: F401  (fixture)

T0 = dt.datetime(2025, 6, 1, 8, 0, tzinfo=dt.UTC)


def _obs(run_id: int, day: float, evidence: int, level: float) -> Observation:
    return Observation(run_id=run_id, day=day, start_m=14_420.0, end_m=14_430.0, centre_m=14_425.0, peak_m=14_425.0,
                       level=level, change=-0.45, tier=1, severity=abs(level) / 0.30, evidence=evidence, wheels=15)


def _write(session, line, run_id: int, day: float, known: list[PlaceState], trends=None) -> Place:
    by_id = {p.id: p for p in session.scalars(select(Place).where(Place.line_key == line.id))}
    before = {i: (p.active, p.listed, []) for i, p in by_id.items()}
    write_run(session, line, run_id, T0 + dt.timedelta(days=day), "v1", known, by_id, before, [], [], {},
              np.arange(1440, 1445), ["11", "12", "41", "42"], np.full(5, 90.0), {}, DEFAULT_PLACES_CONFIG,
              trends=trends)
    session.flush()
    return session.get(Place, known[0].id)


def _place(evidence: int) -> PlaceState:
    return PlaceState(id=1, direction=-1, start_m=14_420.0, end_m=14_430.0, peak_m=14_425.0, cls="b91_pads", tier=1,
                      listed=True, observations=[_obs(20, 300.0, EVIDENCE_STEP, -0.7), _obs(22, 330.0, evidence, -0.8)])


def test_a_developing_place_keeps_its_trends_outlook_while_runs_do_not_read_it(db):  # noqa: F811
    # its segment's history: −0.2 → −0.8 over 150 days (the severity, level / alert limit, grows)
    days = np.arange(180.0, 331.0, 15.0)
    trend = linear_trend(days, -1.0 * np.linspace(-0.2, -0.8, days.size) / 0.30, now_day=330.0)
    assert trend.significant and trend.rate_per_year > 0
    with db.write() as s:
        line = ConditionLine(line_id="REAL", track="1", bin_length_m=0.25)
        s.add(line)
        s.flush()
        st = _place(EVIDENCE_TREND)
        row = _write(s, line, 22, 330.0, [st], trends={1: trend})
        rate, days_to, tendency = row.rate_per_year, row.days_to_next, row.tendency
        assert rate is not None and days_to is not None and tendency == "growing"
        # two later runs without a reading of it (no observation, no trend of theirs): the outlook stays
        for run_id, day in ((23, 345.0), (24, 360.0)):
            row = _write(s, line, run_id, day, [st])
            assert (row.rate_per_year, row.days_to_next, row.tendency) == (rate, days_to, tendency)
            assert row.last_run_id == 22

    # a place found by its step, not its trend: the outlook is over its observations (two: too few for a rate)
    with db.write() as s:
        line = ConditionLine(line_id="REAL2", track="1", bin_length_m=0.25)
        s.add(line)
        s.flush()
        st = _place(EVIDENCE_STEP)
        st.id = 2
        row = _write(s, line, 22, 330.0, [st], trends={2: trend})
        assert row.rate_per_year is not None  # the trend given
        row = _write(s, line, 23, 345.0, [st])
        assert row.rate_per_year is None and row.days_to_next is None
