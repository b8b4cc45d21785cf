"""Plain queries of the segment condition store's tables: a line's entry, a run's rows deleted.

What goes into the rows (alignment, index, change tests, flags) is decided by
:mod:`app.condition.writer`; what is read back for the API by :mod:`app.condition.readers`.
"""

from __future__ import annotations

from sqlalchemy import delete, select, update
from sqlalchemy.orm import Session

from app.db.models import (
    ConditionFlag,
    ConditionLine,
    ConditionOverview,
    ConditionRun,
    SegmentCondition,
)

__all__ = ["line_of", "delete_run_condition"]


def line_of(session: Session, line_id: str, track: str, bin_length_m: float = 0.25) -> ConditionLine:
    """The store's entry of a line and track, created when missing."""
    line = session.scalar(
        select(ConditionLine).where(ConditionLine.line_id == line_id, ConditionLine.track == track)
    )
    if line is None:
        line = ConditionLine(line_id=line_id, track=track, bin_length_m=bin_length_m)
        session.add(line)
        session.flush()
    return line


def delete_run_condition(session: Session, run_id: int) -> None:
    """Delete a run's segment rows, overview, flags and entry (reprocessing, deletion).

    A line left without runs loses its alignment reference (the next run stored
    becomes it): the run may have left because its line was wrong
    (``PATCH /runs/{id}`` of the metadata), so its signature must not stay the
    reference of that line.
    """
    line_key = session.scalar(select(ConditionRun.line_key).where(ConditionRun.run_id == run_id))
    session.execute(delete(SegmentCondition).where(SegmentCondition.run_id == run_id))
    session.execute(delete(ConditionOverview).where(ConditionOverview.run_id == run_id))
    session.execute(delete(ConditionFlag).where(ConditionFlag.run_id == run_id))
    session.execute(delete(ConditionRun).where(ConditionRun.run_id == run_id))
    if line_key is not None and session.scalar(
            select(ConditionRun.run_id).where(ConditionRun.line_key == line_key).limit(1)) is None:
        session.execute(update(ConditionLine).where(ConditionLine.id == line_key).values(
            ref_run_id=None, ref_first_bin=None, ref_signature=None, km_min=None, km_max=None))
