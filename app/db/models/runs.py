"""Tables of runs and what processing made of them (portable: SQLite and PostgreSQL).

Tables
------
runs          one measurement run: metadata columns used for filtering, the full
              metadata as JSON, sha256 of the uploaded file (unique), run file path
jobs          processing jobs of a run (status, progress, settings, provenance)
job_chunks    the chunks of a job; unique (job_id, chunk_index)
profile_bins  per run, wheel and 25 cm bin: indicators; primary key (run_id, wheel, bin)
wheel_oor     per run and wheel: OOR orders and reconstructed radius deviation

Raw arrays never live here: they stay in the run store. Deleting a run deletes
its jobs, chunks, profile bins and wheels (``ON DELETE CASCADE``; the CRUD
functions also delete children explicitly so SQLite without foreign keys
behaves the same).
"""

from __future__ import annotations

import datetime as dt
from typing import Any

from sqlalchemy import (
    BigInteger,
    Boolean,
    Float,
    ForeignKey,
    Index,
    Integer,
    SmallInteger,
    String,
    Text,
    UniqueConstraint,
    text,
)
from sqlalchemy.orm import Mapped, mapped_column, relationship

from app.db.models.base import Base, JSONType, UTCDateTime, utcnow

__all__ = [
    "Run",
    "Job",
    "JobChunk",
    "ProfileBin",
    "WheelOOR",
    "JobStatus",
    "ChunkStatus",
    "COARSE_DISPLAY_LEVEL",
    "ORDER_COLUMNS",
    "N_ORDER_COLUMNS",
    "PROFILE_VALUE_COLUMNS",
]

N_ORDER_COLUMNS = 11
#: Lowest display level in the partial display index of ``profile_bins``
#: (level k keeps at most two rows per 4**k bins: levels >= 2 hold 1/8 of the rows).
COARSE_DISPLAY_LEVEL = 2
_COARSE_ROWS = text(f"display_level >= {COARSE_DISPLAY_LEVEL}")  # that index's predicate
_IMPACT_ROWS = text("track_impact_mm IS NOT NULL")
ORDER_COLUMNS: tuple[str, ...] = tuple(f"order_amp_{i:02d}" for i in range(1, N_ORDER_COLUMNS + 1))
#: Indicator columns of a profile bin, in the order of the export files.
PROFILE_VALUE_COLUMNS: tuple[str, ...] = (
    "n_samples",
    "speed_mean",
    "sleeper_amp",
    "sleeper_2_amp",
    "sleeper_3_amp",
    "sleeper_rms",
    *ORDER_COLUMNS,
    "residual_rms",
    "sleeper_force_amp",
    "sleeper_amp_raw",
    "sleeper_amp_sd",
    "sleeper_amp_sd_shared",
    "track_impact_mm",
    "sleeper_step",
)


class JobStatus:
    """Values of ``jobs.status``."""

    QUEUED = "queued"
    RUNNING = "running"
    DONE = "done"
    FAILED = "failed"
    CANCELLED = "cancelled"
    ACTIVE = (QUEUED, RUNNING)
    FINAL = (DONE, FAILED, CANCELLED)
    ALL = (QUEUED, RUNNING, DONE, FAILED, CANCELLED)


class ChunkStatus:
    """Values of ``job_chunks.status``."""

    PENDING = "pending"
    RUNNING = "running"
    DONE = "done"
    FAILED = "failed"


class Run(Base):
    """One measurement run."""

    __tablename__ = "runs"
    __table_args__ = (
        Index("ix_runs_line_id_start_time", "line_id", "start_time"),
        {"sqlite_autoincrement": True},
    )

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    sha256: Mapped[str] = mapped_column(String(64), unique=True)
    file_path: Mapped[str] = mapped_column(String(255))
    source_format: Mapped[str] = mapped_column(String(16))
    original_filename: Mapped[str | None] = mapped_column(String(255))
    size_bytes: Mapped[int] = mapped_column(BigInteger)
    vehicle_id: Mapped[str | None] = mapped_column(String(128), index=True)
    line_id: Mapped[str | None] = mapped_column(String(128), index=True)
    track: Mapped[str | None] = mapped_column(String(64))
    direction: Mapped[str | None] = mapped_column(String(64))
    start_time: Mapped[dt.datetime | None] = mapped_column(UTCDateTime(), index=True)
    km_start: Mapped[float | None] = mapped_column(Float)
    km_increasing: Mapped[bool | None] = mapped_column(Boolean)
    fs: Mapped[float] = mapped_column(Float)
    n_samples: Mapped[int] = mapped_column(BigInteger)
    duration_s: Mapped[float] = mapped_column(Float)
    distance_m: Mapped[float | None] = mapped_column(Float)
    speed_min: Mapped[float | None] = mapped_column(Float)
    speed_max: Mapped[float | None] = mapped_column(Float)
    channels: Mapped[list[str]] = mapped_column(JSONType)
    meta: Mapped[dict[str, Any]] = mapped_column("metadata", JSONType)
    #: what ingest reported: {"warnings": [...], "report": {...}} (RunSummary.warnings/.report)
    ingest_report: Mapped[dict[str, Any] | None] = mapped_column(JSONType)
    created_by: Mapped[str | None] = mapped_column(String(128))
    created_at: Mapped[dt.datetime] = mapped_column(UTCDateTime(), default=utcnow)
    #: when the retention sweep removed the run's 25 cm rows (its segment condition rows stay)
    profiles_swept_at: Mapped[dt.datetime | None] = mapped_column(UTCDateTime())

    jobs: Mapped[list[Job]] = relationship(
        back_populates="run", passive_deletes=True, order_by="Job.id"
    )


class Job(Base):
    """A processing job of a run."""

    __tablename__ = "jobs"
    __table_args__ = (
        Index("ix_jobs_status_created_at", "status", "created_at"),
        {"sqlite_autoincrement": True},
    )

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    run_id: Mapped[int] = mapped_column(
        ForeignKey("runs.id", ondelete="CASCADE"), index=True
    )
    status: Mapped[str] = mapped_column(String(16), default=JobStatus.QUEUED)
    progress: Mapped[float] = mapped_column(Float, default=0.0)
    error: Mapped[str | None] = mapped_column(Text)
    settings: Mapped[dict[str, Any]] = mapped_column(JSONType)
    meta: Mapped[dict[str, Any] | None] = mapped_column(JSONType)
    n_chunks: Mapped[int | None] = mapped_column(Integer)
    cancel_requested: Mapped[bool] = mapped_column(Boolean, default=False)
    attempts: Mapped[int] = mapped_column(Integer, default=0)
    worker_id: Mapped[str | None] = mapped_column(String(128))
    heartbeat_at: Mapped[dt.datetime | None] = mapped_column(UTCDateTime())
    created_by: Mapped[str | None] = mapped_column(String(128))
    created_at: Mapped[dt.datetime] = mapped_column(UTCDateTime(), default=utcnow)
    started_at: Mapped[dt.datetime | None] = mapped_column(UTCDateTime())
    finished_at: Mapped[dt.datetime | None] = mapped_column(UTCDateTime())

    run: Mapped[Run] = relationship(back_populates="jobs")


class JobChunk(Base):
    """One chunk of a job; its result file is the proof that it is done."""

    __tablename__ = "job_chunks"
    __table_args__ = (UniqueConstraint("job_id", "chunk_index"),)

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    job_id: Mapped[int] = mapped_column(ForeignKey("jobs.id", ondelete="CASCADE"), index=True)
    chunk_index: Mapped[int] = mapped_column(Integer)
    status: Mapped[str] = mapped_column(String(16), default=ChunkStatus.PENDING)
    spec: Mapped[dict[str, Any]] = mapped_column(JSONType)
    result_path: Mapped[str | None] = mapped_column(String(512))
    started_at: Mapped[dt.datetime | None] = mapped_column(UTCDateTime())
    finished_at: Mapped[dt.datetime | None] = mapped_column(UTCDateTime())


class ProfileBin(Base):
    """Indicators of one wheel in one track bin (default 25 cm), as computed by one job.

    The largest table by far (about a million rows per 30-minute run). Rows are
    keyed by the job that computed them: the rows of a run that readers see are
    those of its latest done job (:func:`app.db.results_reader.results_job_id`), so a new
    job's rows can be written wheel by wheel, in parallel, while readers keep
    seeing the previous results; marking the job done publishes them and drops
    the older job's rows in one transaction.

    No foreign-key constraints: PostgreSQL checks a foreign key row by row,
    which tripled the time to store a run. The rows are tied to their run by
    the code: they are written while the run row is locked against deletion
    (:func:`app.db.results_writer.lock_run_for_results`), and
    :func:`app.db.crud.delete_run` locks the run, then deletes them.

    ``display_level`` ranks every bin for display (a min–max pyramid of the
    sleeper-passage amplitude, :func:`app.analysis.aggregate.display_levels`).
    Two indexes: the primary key serves km ranges as bin ranges (the bin centre
    is ``(bin + 0.5) × bin length``, :func:`app.db.results_reader.profile_where`), and a
    partial index (job, wheel, km, level) over the rows of level
    ≥ :data:`COARSE_DISPLAY_LEVEL` (one row in eight) serves plots of long
    ranges, filtering the level inside the index. Being partial, it costs an
    eighth of a full index when ~10⁶ rows are stored (a full one was a third of
    PostgreSQL's work, and two workers storing at once contended on it).
    """

    __tablename__ = "profile_bins"
    __table_args__ = (
        Index(
            "ix_profile_bins_coarse_display", "job_id", "wheel", "km", "display_level",
            postgresql_where=_COARSE_ROWS,
            sqlite_where=_COARSE_ROWS,
        ),
        # the few bins holding a track impact, for a run's list of them (app.db.track_impacts)
        Index("ix_profile_bins_track_impacts", "job_id", "km",
              postgresql_where=_IMPACT_ROWS, sqlite_where=_IMPACT_ROWS),
    )

    job_id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=False)
    wheel: Mapped[str] = mapped_column(String(8), primary_key=True)
    bin: Mapped[int] = mapped_column(BigInteger, primary_key=True, autoincrement=False)
    run_id: Mapped[int] = mapped_column(Integer)
    km: Mapped[float] = mapped_column(Float)
    display_level: Mapped[int] = mapped_column(SmallInteger, default=0, server_default="0")
    n_samples: Mapped[int] = mapped_column(Integer)
    speed_mean: Mapped[float | None] = mapped_column(Float)
    sleeper_amp: Mapped[float | None] = mapped_column(Float)
    #: sleeper-passage harmonics 2·f_s and 3·f_s (peak, m/s²) and the RMS over the fundamental
    #: and the harmonics extracted (the energy indicator, m/s²); NULL in jobs before issue 15
    sleeper_2_amp: Mapped[float | None] = mapped_column(Float)
    sleeper_3_amp: Mapped[float | None] = mapped_column(Float)
    sleeper_rms: Mapped[float | None] = mapped_column(Float)
    order_amp_01: Mapped[float | None] = mapped_column(Float)
    order_amp_02: Mapped[float | None] = mapped_column(Float)
    order_amp_03: Mapped[float | None] = mapped_column(Float)
    order_amp_04: Mapped[float | None] = mapped_column(Float)
    order_amp_05: Mapped[float | None] = mapped_column(Float)
    order_amp_06: Mapped[float | None] = mapped_column(Float)
    order_amp_07: Mapped[float | None] = mapped_column(Float)
    order_amp_08: Mapped[float | None] = mapped_column(Float)
    order_amp_09: Mapped[float | None] = mapped_column(Float)
    order_amp_10: Mapped[float | None] = mapped_column(Float)
    order_amp_11: Mapped[float | None] = mapped_column(Float)
    residual_rms: Mapped[float | None] = mapped_column(Float)
    sleeper_force_amp: Mapped[float | None] = mapped_column(Float)
    #: issue 26: the single-wheel VKF amplitude at f_s (what sleeper_amp was before: sleeper_amp is now the
    #: roughness-corrected best estimate) and the 1-σ of sleeper_amp, m/s²; NULL in jobs before issue 26
    sleeper_amp_raw: Mapped[float | None] = mapped_column(Float)
    sleeper_amp_sd: Mapped[float | None] = mapped_column(Float)
    #: the part of sleeper_amp_sd shared along the ≈ 20 m floor window (what a single wheel's floor leaves)
    sleeper_amp_sd_shared: Mapped[float | None] = mapped_column(Float)
    #: estimated depth (mm) of an isolated track impact (dipped weld or joint) in this bin, NULL elsewhere;
    #: the sleeper-passage columns are bridged around it (app.pipeline.impacts); NULL in jobs before issue 26
    track_impact_mm: Mapped[float | None] = mapped_column(Float)
    #: the step estimate of sleeper_amp: its levels between change points, m/s² (issue 33 item 7,
    #: app.pipeline.assemble.sleeper_step); NULL where sleeper_amp is, and in jobs before migration 0025
    sleeper_step: Mapped[float | None] = mapped_column(Float)


class WheelOOR(Base):
    """Out-of-roundness of one wheel over a run."""

    __tablename__ = "wheel_oor"

    run_id: Mapped[int] = mapped_column(
        ForeignKey("runs.id", ondelete="CASCADE"), primary_key=True
    )
    wheel: Mapped[str] = mapped_column(String(8), primary_key=True)
    job_id: Mapped[int | None] = mapped_column(ForeignKey("jobs.id", ondelete="CASCADE"), index=True)
    wheel_diameter_m: Mapped[float | None] = mapped_column(Float)
    n_windows: Mapped[int | None] = mapped_column(Integer)
    orders: Mapped[list[dict[str, Any]]] = mapped_column(JSONType)
    angles_deg: Mapped[list[float]] = mapped_column(JSONType)
    profile_um: Mapped[list[float]] = mapped_column(JSONType)
    profile_p05_um: Mapped[list[float] | None] = mapped_column(JSONType)
    profile_p95_um: Mapped[list[float] | None] = mapped_column(JSONType)
    extra: Mapped[dict[str, Any] | None] = mapped_column(JSONType)
