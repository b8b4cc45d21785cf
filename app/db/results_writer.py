"""The results writer: a job's profile rows and wheel rows into SQL.

Results are written in two steps, so that readers switch from a run's old
results to its new ones at one commit and a retried write never duplicates
rows: :func:`store_profile_rows` writes a job's profile rows (ranked for
display, not yet shown), :func:`publish_results` makes them the run's in the
transaction that marks the job done, and :func:`discard_profile_rows` removes
those of a job that failed or was cancelled. Every writer takes the run's lock
first (:func:`lock_run_for_results`).

Profile rows go in as a binary ``COPY`` on PostgreSQL (the stream laid out by
:mod:`app.db.pg_copy`), as batched inserts elsewhere (:mod:`app.db.bulk`). They are read by
:mod:`app.db.results_reader` and :mod:`app.db.display`.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import pandas as pd
from sqlalchemy import delete, insert, select, update
from sqlalchemy.orm import Session

from app.analysis.aggregate import display_levels
from app.core.jsonable import jsonable
from app.db.bulk import insert_frame
from app.db.models import PROFILE_VALUE_COLUMNS, Job, ProfileBin, Run, WheelOOR

__all__ = [
    "lock_run_for_results",
    "store_profile_rows",
    "publish_results",
    "discard_profile_rows",
]

_INSERT_BATCH = 20_000
#: PostgreSQL binary type of every column of a stored profile row (see _profile_frame)
_PG_COPY_TYPES: dict[str, str] = {
    "run_id": "int4", "job_id": "int4", "wheel": "text", "bin": "int8", "km": "float8",
    "display_level": "int2", "n_samples": "int4",
    **{c: "float8" for c in PROFILE_VALUE_COLUMNS if c != "n_samples"},
}


def _profile_frame(profiles: pd.DataFrame, run_id: int, job_id: int) -> pd.DataFrame:
    """The rows to insert as a numeric frame in column order (NaN where no value)."""
    required = ("wheel", "bin", "km", "n_samples")
    missing = [c for c in required if c not in profiles.columns]
    if missing:
        raise ValueError(f"profiles: missing column(s) {', '.join(missing)}")
    n = len(profiles)
    out: dict[str, np.ndarray] = {
        "run_id": np.full(n, run_id, dtype=np.int64),
        "job_id": np.full(n, job_id, dtype=np.int64),
        "wheel": profiles["wheel"].astype(str).to_numpy(),
        "bin": profiles["bin"].to_numpy(dtype=np.int64),
        "km": profiles["km"].to_numpy(dtype=np.float64),
        "display_level": profiles["display_level"].to_numpy(dtype=np.int16)
        if "display_level" in profiles.columns else np.zeros(n, dtype=np.int16),
        "n_samples": profiles["n_samples"].to_numpy(dtype=np.int64),
    }
    for col in PROFILE_VALUE_COLUMNS:
        if col == "n_samples":
            continue
        if col in profiles.columns:
            values = profiles[col].to_numpy(dtype=np.float64, na_value=np.nan).copy()
            values[~np.isfinite(values)] = np.nan
        else:
            values = np.full(n, np.nan)
        out[col] = values
    return pd.DataFrame(out)


def _insert_profiles(session: Session, frame: pd.DataFrame) -> None:
    """Bulk insert (:func:`app.db.bulk.insert_frame`: binary ``COPY`` on PostgreSQL)."""
    insert_frame(session, ProfileBin.__table__, frame, _PG_COPY_TYPES)


def lock_run_for_results(session: Session, run_id: int) -> bool:
    """Lock run ``run_id`` against deletion until the transaction ends; False if it is gone.

    Writers of a run's results take this lock (``FOR KEY SHARE`` on PostgreSQL,
    the database write lock on SQLite) before anything else, and
    :func:`app.db.crud.delete_run` locks the run for update first, so a run is never deleted
    halfway through storing its rows, and the two never deadlock.
    """
    stmt = select(Run.id).where(Run.id == run_id).with_for_update(read=True, key_share=True)
    return session.scalar(stmt) is not None


def _with_display_levels(profiles: pd.DataFrame) -> pd.DataFrame:
    """``profiles`` with the column ``display_level`` ranked per wheel by the sleeper amplitude."""
    levels = np.zeros(len(profiles), dtype=np.int16)
    if len(profiles) and "sleeper_amp" in profiles.columns:
        bins = profiles["bin"].to_numpy(dtype=np.int64)
        amp = profiles["sleeper_amp"].to_numpy(dtype=np.float64, na_value=np.nan)
        for rows in profiles.groupby(profiles["wheel"].astype(str), sort=False).indices.values():
            levels[rows] = display_levels(bins[rows], amp[rows])
    return profiles.assign(display_level=levels)


def store_profile_rows(session: Session, run_id: int, job_id: int, profiles: pd.DataFrame) -> int:
    """Write a job's profile rows of the wheels in ``profiles`` (not yet published).

    The job's earlier rows of those wheels are deleted first, so a retried
    write never duplicates rows. The run is locked against deletion first
    (:func:`lock_run_for_results`), and every bin is ranked for display
    (``display_level``, per wheel by the sleeper-passage amplitude). Readers
    see the rows once the job is done (:func:`publish_results` in the same
    transaction as the job's state).

    Parameters
    ----------
    profiles : pandas.DataFrame
        One row per (wheel, bin) with the columns of ``RunResults.profiles``;
        order columns beyond ``order_amp_11`` are not stored in SQL.

    Returns
    -------
    int
        Number of profile rows written.

    Raises
    ------
    LookupError
        If the run does not exist (deleted meanwhile).
    ValueError
        If ``profiles`` lacks a required column.
    """
    if not lock_run_for_results(session, run_id):
        raise LookupError(f"run {run_id} does not exist (deleted?)")
    _profile_frame(profiles.iloc[:0], run_id, job_id)  # checks the columns
    wheels = sorted({str(w) for w in profiles["wheel"].unique()})
    if wheels:
        session.execute(delete(ProfileBin).where(ProfileBin.job_id == job_id, ProfileBin.wheel.in_(wheels)))
    profiles = _with_display_levels(profiles)
    # batch by batch: Python row objects of a whole long run would take ~1 KB a row
    for a in range(0, len(profiles), _INSERT_BATCH):
        _insert_profiles(session, _profile_frame(profiles.iloc[a : a + _INSERT_BATCH], run_id, job_id))
    return len(profiles)


def publish_results(
    session: Session,
    run_id: int,
    job_id: int,
    wheels: Sequence[dict[str, Any]],
) -> None:
    """Make a job's results the run's: wheel rows replaced, other jobs' profile rows deleted.

    Run it in the transaction that marks the job done (that is what readers
    go by, :func:`app.db.results_reader.results_job_id`), with the run locked
    (:func:`lock_run_for_results`), after the job's profile rows are stored:
    the publish step (:func:`app.publish.publish_job`).

    Parameters
    ----------
    wheels : sequence of dict
        ``RunResults.wheels`` (one dict per wheel with a ``wheel`` key).

    Raises
    ------
    ValueError
        If a wheel result has no ``wheel``.
    """
    known = {
        "wheel", "wheel_diameter_m", "n_windows", "orders", "angles_deg",
        "profile_um", "profile_p05_um", "profile_p95_um",
    }
    wheel_rows = []
    for w in wheels:
        if "wheel" not in w:
            raise ValueError("wheels: every wheel result needs a 'wheel' key")
        wheel_rows.append(
            {
                "run_id": run_id,
                "job_id": job_id,
                "wheel": str(w["wheel"]),
                "wheel_diameter_m": jsonable(w.get("wheel_diameter_m")),
                "n_windows": jsonable(w.get("n_windows")),
                "orders": jsonable(w.get("orders", [])),
                "angles_deg": jsonable(w.get("angles_deg", [])),
                "profile_um": jsonable(w.get("profile_um", [])),
                "profile_p05_um": jsonable(w.get("profile_p05_um")),
                "profile_p95_um": jsonable(w.get("profile_p95_um")),
                "extra": jsonable({k: v for k, v in w.items() if k not in known}) or None,
            }
        )
    session.execute(delete(WheelOOR).where(WheelOOR.run_id == run_id))
    if wheel_rows:
        session.execute(insert(WheelOOR), wheel_rows)
    other_jobs = select(Job.id).where(Job.run_id == run_id, Job.id != job_id).scalar_subquery()
    session.execute(delete(ProfileBin).where(ProfileBin.job_id.in_(other_jobs)))
    session.execute(update(Run).where(Run.id == run_id).values(profiles_swept_at=None))  # rows again


def discard_profile_rows(session: Session, job_id: int) -> None:
    """Delete the unpublished profile rows of a job that failed or was cancelled."""
    session.execute(delete(ProfileBin).where(ProfileBin.job_id == job_id))
