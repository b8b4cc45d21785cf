"""The cached reference curves of the stiffness index: one row per line and track.

Computing the curves reads every 25 cm row of every run of a line, so they
are kept here and refreshed when a job of the line is published (the worker)
or on demand (:mod:`app.analytics.reference_curves`).
"""

from __future__ import annotations

import datetime as dt
from typing import Any

from sqlalchemy import Float, Integer, String, UniqueConstraint
from sqlalchemy.orm import Mapped, mapped_column

from app.db.models.base import Base, JSONType, UTCDateTime, utcnow

__all__ = ["ReferenceCurveRow"]


class ReferenceCurveRow(Base):
    """The reference curves of one line and track (``body``: ``ReferenceSet.to_dict()``).

    ``fingerprint`` identifies what they were computed from (the runs' result
    jobs, the superstructure sections, the settings); a different current
    fingerprint means the curves are stale.
    """

    __tablename__ = "reference_curves"
    __table_args__ = (UniqueConstraint("line_id", "track", name="uq_reference_curves_line_id_track"),)

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    line_id: Mapped[str] = mapped_column(String(128))
    track: Mapped[str] = mapped_column(String(64))
    fingerprint: Mapped[str] = mapped_column(String(64))
    run_ids: Mapped[list[int]] = mapped_column(JSONType)
    job_ids: Mapped[list[int]] = mapped_column(JSONType)
    body: Mapped[dict[str, Any]] = mapped_column(JSONType)
    computed_at: Mapped[dt.datetime] = mapped_column(UTCDateTime(), default=utcnow)
    compute_s: Mapped[float] = mapped_column(Float)
