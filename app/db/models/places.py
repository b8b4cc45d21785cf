"""Tables of the places (issue 25, docs/places.md): the work list an engineer acts on.

Tables
------
places                  one row per place of a line and track: its state in the lifecycle
                        (:class:`app.analysis.condition.lifecycle.PlaceState`: direction, extent,
                        peak, class, baseline, tier, listed, active, misses, lower runs, the
                        action whose effect it is), its latest reading and outlook (what the work
                        list ranks by, kept current by the publish step), its workflow status and
                        the method version it was measured with
place_observations      one row per place and run that found or held it (fields of
                        :class:`~app.analysis.condition.lifecycle.Observation`, the run's time and
                        speed over the place, the method version)
place_events            what happened to a place (new, tier_up, tier_down, back, repaired,
                        inactive, linked); ``alerted``: an alert was queued for it
place_status_history    the engineers' status changes (who, when, old, new, comment)
place_actions           maintenance actions over a place (linked, repaired it, or the place is
                        their effect), with the action's kind, date and extent copied (a
                        maintenance import in ``replace`` mode renews the actions' ids)
place_runs              the runs applied to their line's places, in time order, with the method
                        version and the extent they covered (a run is applied once)
places_pending          the published runs whose places update has not been done yet (issue 24: the
                        publish transaction writes the row, the places follow-up deletes it in the
                        commit that applies the run; attempts and back-off of a failing update)

Rows are written by :func:`app.places.update.update_places`, called by the places follow-up of the
publish step (:mod:`app.places.followup`) in its own transaction after the publish commit; only the
status columns and the status history by the workflow (:mod:`app.places.workflow`).
"""

from __future__ import annotations

import datetime as dt

from sqlalchemy import Boolean, Date, Float, ForeignKey, Index, Integer, SmallInteger, String, Text
from sqlalchemy.orm import Mapped, mapped_column

from app.db.models.base import Base, UTCDateTime, utcnow

__all__ = [
    "PLACE_STATUSES",
    "PLACE_EVENT_KINDS",
    "PLACE_ACTION_RELATIONS",
    "Place",
    "PlaceObservation",
    "PlaceEventRow",
    "PlaceStatusChange",
    "PlaceAction",
    "PlaceRun",
    "PlacesPending",
]

#: Workflow statuses of a place (set by engineers; ``back`` reopens a fixed place).
PLACE_STATUSES: tuple[str, ...] = ("open", "acknowledged", "planned", "fixed", "false_alarm")
#: Kinds of place events.
PLACE_EVENT_KINDS: tuple[str, ...] = ("new", "tier_up", "tier_down", "confirmed", "missed", "inactive", "back",
                                      "repaired", "linked")
#: How a maintenance action relates to a place.
PLACE_ACTION_RELATIONS: tuple[str, ...] = ("linked", "repaired", "explained")


class Place(Base):
    """A place of a line and track (one row; ``id`` stays across runs)."""

    __tablename__ = "places"
    __table_args__ = (
        Index("ix_places_line_key_listed_active", "line_key", "listed", "active"),
        {"sqlite_autoincrement": True},
    )

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    line_key: Mapped[int] = mapped_column(Integer)
    # lifecycle state (PlaceState)
    direction: Mapped[int] = mapped_column(SmallInteger)
    start_m: Mapped[float] = mapped_column(Float)
    end_m: Mapped[float] = mapped_column(Float)
    peak_m: Mapped[float] = mapped_column(Float)
    centre_m: Mapped[float] = mapped_column(Float)
    cls: Mapped[str | None] = mapped_column(String(64))
    baseline: Mapped[float | None] = mapped_column(Float)
    explained_by: Mapped[int | None] = mapped_column(Integer)
    tier: Mapped[int] = mapped_column(SmallInteger, default=0)
    listed: Mapped[bool] = mapped_column(Boolean, default=False)
    active: Mapped[bool] = mapped_column(Boolean, default=True)
    misses: Mapped[int] = mapped_column(Integer, default=0)
    lower_runs: Mapped[int] = mapped_column(Integer, default=0)
    # latest reading and outlook (what the work list shows and ranks by)
    level: Mapped[float] = mapped_column(Float)
    change: Mapped[float | None] = mapped_column(Float)
    severity: Mapped[float] = mapped_column(Float, default=0.0)
    # stated 1-sigma of level, change and severity (NULL: none stated)
    level_sd: Mapped[float | None] = mapped_column(Float)
    change_sd: Mapped[float | None] = mapped_column(Float)
    severity_sd: Mapped[float | None] = mapped_column(Float)
    evidence: Mapped[int] = mapped_column(Integer, default=0)
    wheels: Mapped[int] = mapped_column(Integer, default=0)
    wheel_labels: Mapped[str] = mapped_column(String(200), default="")
    runs_confirming: Mapped[int] = mapped_column(Integer, default=0)
    tendency: Mapped[str] = mapped_column(String(16), default="new")
    rate_per_year: Mapped[float | None] = mapped_column(Float)
    rate_low: Mapped[float | None] = mapped_column(Float)
    rate_high: Mapped[float | None] = mapped_column(Float)
    next_limit: Mapped[float | None] = mapped_column(Float)
    days_to_next: Mapped[float | None] = mapped_column(Float)
    first_run_id: Mapped[int] = mapped_column(Integer)
    last_run_id: Mapped[int] = mapped_column(Integer)
    first_seen: Mapped[dt.datetime] = mapped_column(UTCDateTime())
    last_confirmed: Mapped[dt.datetime] = mapped_column(UTCDateTime())
    method_version: Mapped[str] = mapped_column(String(80))
    # workflow
    status: Mapped[str] = mapped_column(String(16), default="open")
    status_comment: Mapped[str | None] = mapped_column(Text)
    status_by: Mapped[str | None] = mapped_column(String(128))
    status_at: Mapped[dt.datetime | None] = mapped_column(UTCDateTime())
    created_at: Mapped[dt.datetime] = mapped_column(UTCDateTime(), default=utcnow)
    updated_at: Mapped[dt.datetime] = mapped_column(UTCDateTime(), default=utcnow)


class PlaceObservation(Base):
    """What one run found (or held) of a place."""

    __tablename__ = "place_observations"
    __table_args__ = (Index("ix_place_observations_place_id_day", "place_id", "day"),)

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    place_id: Mapped[int] = mapped_column(ForeignKey("places.id", ondelete="CASCADE"))
    run_id: Mapped[int] = mapped_column(Integer, index=True)
    run_time: Mapped[dt.datetime] = mapped_column(UTCDateTime())
    day: Mapped[float] = mapped_column(Float)
    start_m: Mapped[float] = mapped_column(Float)
    end_m: Mapped[float] = mapped_column(Float)
    centre_m: Mapped[float] = mapped_column(Float)
    peak_m: Mapped[float] = mapped_column(Float)
    level: Mapped[float] = mapped_column(Float)
    change: Mapped[float | None] = mapped_column(Float)
    tier: Mapped[int] = mapped_column(SmallInteger)
    severity: Mapped[float] = mapped_column(Float)
    level_sd: Mapped[float | None] = mapped_column(Float)
    change_sd: Mapped[float | None] = mapped_column(Float)
    severity_sd: Mapped[float | None] = mapped_column(Float)
    evidence: Mapped[int] = mapped_column(Integer)
    wheels: Mapped[int] = mapped_column(Integer)
    wheel_labels: Mapped[str] = mapped_column(String(200), default="")
    speed_kmh: Mapped[float | None] = mapped_column(Float)
    method_version: Mapped[str] = mapped_column(String(80))


class PlaceEventRow(Base):
    """An event of a place (``id`` increases: the order of the events)."""

    __tablename__ = "place_events"
    __table_args__ = (Index("ix_place_events_place_id_id", "place_id", "id"), {"sqlite_autoincrement": True})

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    place_id: Mapped[int] = mapped_column(ForeignKey("places.id", ondelete="CASCADE"))
    run_id: Mapped[int | None] = mapped_column(Integer)
    kind: Mapped[str] = mapped_column(String(16))
    old_tier: Mapped[int | None] = mapped_column(SmallInteger)
    new_tier: Mapped[int | None] = mapped_column(SmallInteger)
    action_id: Mapped[int | None] = mapped_column(Integer)
    alerted: Mapped[bool] = mapped_column(Boolean, default=False)
    time: Mapped[dt.datetime] = mapped_column(UTCDateTime())
    created_at: Mapped[dt.datetime] = mapped_column(UTCDateTime(), default=utcnow)


class PlaceStatusChange(Base):
    """An engineer's status change of a place."""

    __tablename__ = "place_status_history"
    __table_args__ = (Index("ix_place_status_history_place_id_id", "place_id", "id"),)

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    place_id: Mapped[int] = mapped_column(ForeignKey("places.id", ondelete="CASCADE"))
    by: Mapped[str] = mapped_column(String(128))
    at: Mapped[dt.datetime] = mapped_column(UTCDateTime(), default=utcnow)
    old: Mapped[str] = mapped_column(String(16))
    new: Mapped[str] = mapped_column(String(16))
    comment: Mapped[str] = mapped_column(Text)


class PlaceAction(Base):
    """A maintenance action over a place."""

    __tablename__ = "place_actions"

    place_id: Mapped[int] = mapped_column(ForeignKey("places.id", ondelete="CASCADE"), primary_key=True)
    action_id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=False)
    relation: Mapped[str] = mapped_column(String(16))
    kind: Mapped[str] = mapped_column(String(32))
    date: Mapped[dt.date] = mapped_column(Date)
    km_from: Mapped[float] = mapped_column(Float)
    km_to: Mapped[float] = mapped_column(Float)


class PlaceRun(Base):
    """A run applied to its line's places."""

    __tablename__ = "place_runs"
    __table_args__ = (Index("ix_place_runs_line_key_run_time", "line_key", "run_time"),)

    run_id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=False)
    line_key: Mapped[int] = mapped_column(Integer)
    run_time: Mapped[dt.datetime] = mapped_column(UTCDateTime())
    method_version: Mapped[str] = mapped_column(String(80))
    start_m: Mapped[float] = mapped_column(Float)
    end_m: Mapped[float] = mapped_column(Float)
    n_places: Mapped[int] = mapped_column(Integer)
    n_events: Mapped[int] = mapped_column(Integer)
    applied_at: Mapped[dt.datetime] = mapped_column(UTCDateTime(), default=utcnow)


class PlacesPending(Base):
    """A published run whose places update is still to be done (:mod:`app.places.followup`).

    Written in the publish transaction (a reprocessed run's row is reset), deleted in the follow-up's
    commit that applies the run to its line's places. ``attempts``, ``next_attempt_at`` and ``last_error``
    follow a failing update (retried with back-off); ``gave_up``: failed ``places_max_attempts`` times,
    kept for the operator and no longer holding up the line's later runs.
    """

    __tablename__ = "places_pending"
    __table_args__ = (Index("ix_places_pending_line_key_run_time", "line_key", "run_time"),)

    run_id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=False)
    line_key: Mapped[int] = mapped_column(Integer)
    job_id: Mapped[int] = mapped_column(Integer)
    run_time: Mapped[dt.datetime] = mapped_column(UTCDateTime())
    queued_at: Mapped[dt.datetime] = mapped_column(UTCDateTime(), default=utcnow)
    attempts: Mapped[int] = mapped_column(Integer, default=0)
    next_attempt_at: Mapped[dt.datetime | None] = mapped_column(UTCDateTime())
    last_error: Mapped[str | None] = mapped_column(Text)
    gave_up: Mapped[bool] = mapped_column(Boolean, default=False)
