"""Partitions of ``profile_bins`` on PostgreSQL: by range of ``job_id``, ``PARTITION_JOBS`` jobs each.

A job's rows go to the partition of its id range (``profile_bins_j<start>``),
created ahead by :func:`ensure_for_job` in its own short transaction before the
rows are written (creating a partition locks the parent table briefly; inside
the long transaction that stores a run it would hold readers up). A default
partition takes rows of any range without one. Retention drops whole
partitions of old jobs (:mod:`app.db.retention`). Migration
``0013_profile_partitions`` made the table partitioned and attached the rows
stored before as the first partition. SQLite tables are not partitioned: every
function here does nothing there.
"""

from __future__ import annotations

import logging
import re
from typing import NamedTuple

from sqlalchemy import text
from sqlalchemy.exc import DBAPIError
from sqlalchemy.orm import Session

from app.db.session import Database

__all__ = ["PARTITION_JOBS", "PREFIX", "Partition", "is_partitioned", "list_partitions", "ensure_for_job",
           "drop_partition"]

log = logging.getLogger(__name__)

#: Jobs per partition (the migration keeps its own copy).
PARTITION_JOBS = 1000
#: Name prefix of the job-range partitions.
PREFIX = "profile_bins_j"
_BOUND = re.compile(r"FROM \((MINVALUE|-?\d+)\) TO \((MAXVALUE|-?\d+)\)")
_known: set[tuple[str, int]] = set()


class Partition(NamedTuple):
    """A partition of ``profile_bins`` and its job-id range ``[lo, hi)`` (None: MINVALUE / MAXVALUE)."""

    name: str
    lo: int | None
    hi: int | None
    is_default: bool


def is_partitioned(session: Session) -> bool:
    """Whether ``profile_bins`` is a partitioned table (PostgreSQL after migration 0013)."""
    if session.get_bind().dialect.name != "postgresql":
        return False
    kind = session.execute(text("SELECT relkind FROM pg_class WHERE relname = 'profile_bins' "
                                "AND relnamespace = current_schema()::regnamespace")).scalar()
    return kind == "p"


def list_partitions(session: Session) -> list[Partition]:
    """The partitions of ``profile_bins`` with their job-id ranges (empty on SQLite)."""
    if not is_partitioned(session):
        return []
    rows = session.execute(text(
        "SELECT c.relname, pg_get_expr(c.relpartbound, c.oid) FROM pg_inherits i "
        "JOIN pg_class c ON c.oid = i.inhrelid WHERE i.inhparent = 'profile_bins'::regclass ORDER BY c.relname"
    )).all()
    out = []
    for name, bound in rows:
        if bound == "DEFAULT":
            out.append(Partition(name, None, None, True))
            continue
        m = _BOUND.search(bound or "")
        lo = None if not m or m.group(1) == "MINVALUE" else int(m.group(1))
        hi = None if not m or m.group(2) == "MAXVALUE" else int(m.group(2))
        out.append(Partition(name, lo, hi, False))
    return out


def ensure_for_job(db: Database, job_id: int, size: int = PARTITION_JOBS) -> None:
    """Create the partitions of job ``job_id``'s range and the next one if missing (PostgreSQL).

    Its own transaction. A range whose rows already went to the default
    partition cannot get its partition (PostgreSQL refuses); the rows then
    stay in the default partition, which the sweep deletes from row by row.
    """
    if db.engine.dialect.name != "postgresql":
        return
    start = job_id // size * size
    for lo in (start, start + size):
        key = (db.url, lo)
        if key in _known:
            continue
        name = f"{PREFIX}{lo:010d}"
        try:
            with db.write() as session:
                if not is_partitioned(session):
                    return
                covered = session.execute(text(
                    "SELECT 1 FROM pg_inherits i JOIN pg_class c ON c.oid = i.inhrelid "
                    "WHERE i.inhparent = 'profile_bins'::regclass AND c.relname = :n"), {"n": name}).first()
                if covered is None and not any(p.lo is not None and p.hi is not None and p.lo <= lo < p.hi
                                               or p.lo is None and p.hi is not None and lo < p.hi
                                               for p in list_partitions(session) if not p.is_default):
                    session.execute(text(f"CREATE TABLE IF NOT EXISTS {name} PARTITION OF profile_bins "
                                         f"FOR VALUES FROM ({lo}) TO ({lo + size})"))
            _known.add(key)
        except DBAPIError as exc:  # e.g. rows of the range in the default partition, or a concurrent creator
            log.warning("partition %s not created: %s", name, exc.orig)


def drop_partition(session: Session, name: str) -> None:
    """Drop one job-range partition (never the default one)."""
    if not name.startswith(PREFIX) and name != "profile_bins_legacy":
        raise ValueError(f"not a job-range partition of profile_bins: {name!r}")
    session.execute(text(f'DROP TABLE IF EXISTS "{name}"'))
