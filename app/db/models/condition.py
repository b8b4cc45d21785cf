"""Tables of the segment condition store (kept for ever; the 25 cm rows may be swept).

Tables
------
condition_lines      one row per line and track: the alignment reference (the
                     first stored run's 25 cm signature) and the km extent
condition_runs       one row per run in the store: its line, date, alignment
                     shift and the job whose results it holds
segment_condition    per run, segment length (10 m, 100 m), wheel and segment:
                     condition index (+ uncertainty), raw amplitude mean / p95,
                     speed, number of valid bins, and the change tests against
                     the segment's history (baseline, change, scores)
condition_overview   per run and 100 m segment: the index over the wheels and whether
                     the run flagged anything there (the line's heat map)
condition_flags      changes beyond the repeatability, one row per run, segment
                     and test (wheels combined); ``id`` is the feed cursor (``since=``)

Rows are written when a job is published, in the transaction that marks it
done (:func:`app.condition.writer.store_run_condition`); a run's rows are
replaced when it is reprocessed and deleted with it.
"""

from __future__ import annotations

import datetime as dt

from sqlalchemy import (
    REAL,
    BigInteger,
    Boolean,
    Float,
    Index,
    Integer,
    LargeBinary,
    SmallInteger,
    String,
    UniqueConstraint,
)
from sqlalchemy.orm import Mapped, mapped_column

from app.db.models.base import Base, UTCDateTime, utcnow

__all__ = ["ConditionLine", "ConditionRun", "SegmentCondition", "ConditionOverview", "ConditionFlag", "FLAG_KINDS"]

#: Kinds of condition flags: a sudden change, a gradual trend.
FLAG_KINDS: tuple[str, ...] = ("step", "trend")

#: autoincrement id that SQLite never reuses (INTEGER PRIMARY KEY AUTOINCREMENT) and BIGINT elsewhere
_FEED_ID = BigInteger().with_variant(Integer(), "sqlite")


class ConditionLine(Base):
    """A line and track of the condition store.

    ``ref_signature`` is the alignment reference: the mean sleeper-passage
    amplitude over wheels per 25 cm bin (float32, NaN where missing) of the
    first run stored for the line, from bin ``ref_first_bin``. Every later run
    is shifted onto it (:func:`app.analysis.stiffness.alignment.align_runs`),
    so that its segments are the same places on the ground.
    """

    __tablename__ = "condition_lines"
    __table_args__ = (UniqueConstraint("line_id", "track"), {"sqlite_autoincrement": True})

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    line_id: Mapped[str] = mapped_column(String(128))
    track: Mapped[str] = mapped_column(String(64))
    bin_length_m: Mapped[float] = mapped_column(Float)
    ref_run_id: Mapped[int | None] = mapped_column(Integer)
    ref_first_bin: Mapped[int | None] = mapped_column(BigInteger)
    ref_signature: Mapped[bytes | None] = mapped_column(LargeBinary)
    km_min: Mapped[float | None] = mapped_column(Float)
    km_max: Mapped[float | None] = mapped_column(Float)
    created_at: Mapped[dt.datetime] = mapped_column(UTCDateTime(), default=utcnow)


class ConditionRun(Base):
    """A run whose segment rows are in the store."""

    __tablename__ = "condition_runs"
    __table_args__ = (Index("ix_condition_runs_line_key_run_time", "line_key", "run_time"),)

    run_id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=False)
    line_key: Mapped[int] = mapped_column(Integer)
    job_id: Mapped[int] = mapped_column(Integer)
    run_time: Mapped[dt.datetime] = mapped_column(UTCDateTime())
    shift_m: Mapped[float] = mapped_column(Float)
    shift_confidence: Mapped[float | None] = mapped_column(Float)
    n_segments: Mapped[int] = mapped_column(Integer)
    n_flags: Mapped[int] = mapped_column(Integer)
    published_at: Mapped[dt.datetime] = mapped_column(UTCDateTime(), default=utcnow)


class SegmentCondition(Base):
    """Condition of one segment of one wheel in one run.

    Keyed by run first, so a run's rows are contiguous (written and replaced
    together, read run by run for heat maps and histories); the index
    ``(line_key, seg_m, seg)`` serves one segment's trend over all runs.
    Values are single precision (REAL): ample for indices and amplitudes, and
    half the storage on PostgreSQL.
    """

    __tablename__ = "segment_condition"
    __table_args__ = (
        Index("ix_segment_condition_line_key_seg_m_seg", "line_key", "seg_m", "seg"),
        {"sqlite_with_rowid": False},
    )

    run_id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=False)
    seg_m: Mapped[int] = mapped_column(SmallInteger, primary_key=True, autoincrement=False)
    wheel: Mapped[str] = mapped_column(String(8), primary_key=True)
    seg: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=False)
    line_key: Mapped[int] = mapped_column(Integer)
    job_id: Mapped[int] = mapped_column(Integer)
    n_valid: Mapped[int] = mapped_column(Integer)
    amp_mean: Mapped[float] = mapped_column(REAL)
    amp_p95: Mapped[float] = mapped_column(REAL)
    speed_mean: Mapped[float] = mapped_column(REAL)
    condition_index: Mapped[float] = mapped_column(REAL)
    condition_index_sd: Mapped[float | None] = mapped_column(REAL)
    n_history: Mapped[int] = mapped_column(SmallInteger, default=0)
    baseline: Mapped[float | None] = mapped_column(REAL)
    change: Mapped[float | None] = mapped_column(REAL)
    change_z: Mapped[float | None] = mapped_column(REAL)
    trend_rate: Mapped[float | None] = mapped_column(REAL)
    trend_z: Mapped[float | None] = mapped_column(REAL)


class ConditionOverview(Base):
    """A run's 100 m segment as the line overview (heat map runs × km) shows it.

    ``condition_index`` is the mean of the wheels' 100 m index, ``flagged`` whether any
    flag of the run (10 m or 100 m) lies in the segment: the heat map of a
    year of daily runs reads these ~500 rows per 50 km run instead of
    averaging four times as many segment rows.
    """

    __tablename__ = "condition_overview"

    run_id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=False)
    seg: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=False)
    line_key: Mapped[int] = mapped_column(Integer)
    condition_index: Mapped[float] = mapped_column(REAL)
    n_wheels: Mapped[int] = mapped_column(SmallInteger)
    flagged: Mapped[bool] = mapped_column(Boolean, default=False)


class ConditionFlag(Base):
    """A change beyond the repeatability: one run, segment and test.

    The wheels' scores are combined (:func:`app.analysis.condition.combine_wheels`);
    ``wheels`` lists those that agree (comma-separated), ``score`` is the combined
    score, ``change`` the mean change of the index and ``rate_per_year`` the mean
    trend over the wheels.
    ``id`` grows in commit order (flags are inserted under a transaction lock
    on PostgreSQL; SQLite writes one transaction at a time), so a data system
    polling with ``since=<last id>`` never misses one. ``is_new``: the
    segment's previous run was not flagged by the same test in the same
    direction (what alerts are sent for).
    """

    __tablename__ = "condition_flags"
    __table_args__ = (
        Index("ix_condition_flags_run_id", "run_id"),
        Index("ix_condition_flags_line_key_seg_m_seg", "line_key", "seg_m", "seg"),
        {"sqlite_autoincrement": True},
    )

    id: Mapped[int] = mapped_column(_FEED_ID, primary_key=True, autoincrement=True)
    run_id: Mapped[int] = mapped_column(Integer)
    line_key: Mapped[int] = mapped_column(Integer)
    job_id: Mapped[int] = mapped_column(Integer)
    seg_m: Mapped[int] = mapped_column(SmallInteger)
    seg: Mapped[int] = mapped_column(Integer)
    wheels: Mapped[str] = mapped_column(String(32))
    n_wheels: Mapped[int] = mapped_column(SmallInteger)
    kind: Mapped[str] = mapped_column(String(16))
    direction: Mapped[int] = mapped_column(SmallInteger)
    score: Mapped[float] = mapped_column(Float)
    change: Mapped[float | None] = mapped_column(Float)
    rate_per_year: Mapped[float | None] = mapped_column(Float)
    is_new: Mapped[bool] = mapped_column(Boolean)
    created_at: Mapped[dt.datetime] = mapped_column(UTCDateTime(), default=utcnow)
