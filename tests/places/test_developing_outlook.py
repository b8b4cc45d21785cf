"""A developing place keeps the outlook its trend gave it while the runs after do not read it (issue 33: the real
line's developing place, found by its trend, had a time to its next limit on that run and lost it on the next
two, which had no index on its soft segments: its two observations alone are too few for a rate)."""

from __future__ import annotations

import datetime as dt

import numpy as np
import pytest
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


def test_a_developing_place_is_read_where_it_grows():
    """The test demo's case: a place developing softer (−1 ln unit a year) inside a lasting soft spot whose peak
    does not move is read where it grows — at the peak it read "stable" — while a place growing at its peak is
    read there, not at a neighbour that reads faster by chance (the fastest of noisy rates is biased high)."""
    from app.analysis.condition.change import DEFAULT_CHANGE_PARAMS
    from app.places.index import RunIndex
    from app.places.update import developing_segment

    rng = np.random.default_rng(5)
    seg = np.arange(1300, 1320)
    days = 14.0 * np.arange(10)
    base = np.where((seg >= 1305) & (seg < 1319), -0.8, 0.0)[:, None]
    grow = np.where((seg >= 1310) & (seg < 1314), -1.0, 0.0)[:, None] * days[None, :] / 365.25
    grow[seg == 1311] *= 1.6  # the fastest of it, beside the peak
    series = base + grow + rng.normal(0.0, 0.01, (seg.size, days.size))
    series[seg == 1317] -= 0.1  # the lasting spot's peak, steady
    wheels = np.repeat(series[None], 2, axis=0)
    ri = RunIndex(seg=seg, wheels=["11", "12"], index=wheels[:, :, -1], speed=np.full((2, seg.size), 28.0),
                  history=wheels[:, :, :-1], history_days=days[:-1], classes=np.full(seg.size, "b91", dtype=object),
                  history_speed=np.full((2, seg.size, days.size - 1), 28.0))
    passes = ri.passes(DEFAULT_CHANGE_PARAMS)

    def place(peak_m: float) -> PlaceState:
        obs = Observation(run_id=10, day=days[-1], start_m=13_050.0, end_m=13_190.0, centre_m=13_120.0, peak_m=peak_m,
                          level=-0.9, change=-0.1, tier=3, severity=3.6, evidence=EVIDENCE_TREND | 1, wheels=3)
        return PlaceState(id=1, direction=-1, start_m=13_050.0, end_m=13_190.0, peak_m=peak_m, cls="b91", tier=3,
                          listed=True, observations=[obs])

    at_peak = linear_trend(days, -series[seg == 1317][0])
    assert not (at_peak.significant and at_peak.rate_per_year > 0)  # what the peak says: not growing
    k, trend = developing_segment(place(13_175.0), ri, passes, days[-1])
    assert seg[k] == 1311 and trend.significant and trend.rate_per_year == pytest.approx(1.6, rel=0.1)
    k, trend = developing_segment(place(13_125.0), ri, passes, days[-1])  # growing at its peak: read there
    assert seg[k] == 1312 and trend.rate_per_year == pytest.approx(1.0, rel=0.1)
