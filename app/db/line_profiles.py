"""The profile rows of the runs of a line, as the analytics read them.

:func:`runs_with_results` lists the runs of a line and track that have
results, :func:`result_jobs` the job holding each run's results;
:func:`analytics_frame` reads those jobs' rows without the run ends
(``edge_trim_m``: filter end transients), bins slower than a minimum speed and
bins without amplitude. The analytics endpoints and the reference curves of the
stiffness index read the same rows through here.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pandas as pd
from sqlalchemy import func, select
from sqlalchemy.orm import Session

from app.db import results_reader
from app.db.models import Job, JobStatus, ProfileBin, Run

__all__ = ["ANALYTICS_COLUMNS", "runs_with_results", "result_jobs", "analytics_frame"]

#: Columns of :func:`analytics_frame`.
ANALYTICS_COLUMNS: tuple[str, ...] = ("run_id", "wheel", "bin", "km", "speed_mean", "sleeper_amp", "sleeper_force_amp",
                                       "sleeper_amp_raw")


def runs_with_results(session: Session, line_id: str, track: str | None) -> list[Run]:
    """Runs of a line (and track, if given) with a done job, by start time (then id)."""
    with_results = select(Job.run_id).where(Job.status == JobStatus.DONE)
    stmt = select(Run).where(Run.line_id == line_id, Run.id.in_(with_results))
    if track is not None:
        stmt = stmt.where(Run.track == track)
    runs = list(session.scalars(stmt).all())
    runs.sort(key=lambda r: (r.start_time is None, r.start_time, r.id))
    return runs


def result_jobs(session: Session, runs: Sequence[Run]) -> list[tuple[int, int]]:
    """``(run_id, job_id)`` of the job holding each run's results (runs without results left out)."""
    pairs = [(run.id, results_reader.results_job_id(session, run.id)) for run in runs]
    return [(run_id, job_id) for run_id, job_id in pairs if job_id is not None]


def _wheel_extents(session: Session, job_id: int) -> dict[str, tuple[int, int]]:
    """First and last bin of each wheel of a job (index lookups, not a scan of its rows)."""
    out = {}
    for w in results_reader.stored_profile_wheels(session, job_id):
        where = (ProfileBin.job_id == job_id) & (ProfileBin.wheel == w)
        lo = session.scalar(select(func.min(ProfileBin.bin)).where(where))
        hi = session.scalar(select(func.max(ProfileBin.bin)).where(where))
        out[w] = (int(lo), int(hi))
    return out


def analytics_frame(
    session: Session,
    jobs: Sequence[tuple[int, int]],
    *,
    bin_length_m: float,
    min_speed_kmh: float,
    edge_trim_m: float,
    km_from: float | None = None,
    km_to: float | None = None,
    wheel: str | None = None,
    columns: Sequence[str] = ("speed_mean", "sleeper_amp", "sleeper_force_amp", "sleeper_amp_raw"),
) -> pd.DataFrame:
    """Profile rows of the result jobs ``jobs`` (``(run_id, job_id)`` pairs, :func:`result_jobs`),
    columns ``run_id, wheel, bin, km`` and ``columns``.

    Left out: the first and last ``edge_trim_m`` of each wheel's profile,
    bins slower than ``min_speed_kmh`` and bins without a positive
    ``sleeper_amp``.
    """
    min_v = min_speed_kmh / 3.6
    values = list(dict.fromkeys(["speed_mean", "sleeper_amp", *columns]))
    out_cols = ["run_id", "wheel", "bin", "km", *values]
    k = edge_trim_m / bin_length_m
    frames = []
    for run_id, job_id in jobs:
        ext = _wheel_extents(session, job_id)
        df = results_reader.job_profile_frame(session, job_id, wheel=wheel, km_from=km_from, km_to=km_to,
                                              columns=values)
        if df.empty:
            continue
        wheels = df["wheel"].to_numpy(dtype=object)
        bins = df["bin"].to_numpy()
        lo = np.zeros(len(df), dtype=np.int64)
        hi = np.zeros(len(df), dtype=np.int64)
        for w, (b0, b1) in ext.items():
            m = wheels == w
            lo[m], hi[m] = b0, b1
        keep = (bins >= lo + k) & (bins <= hi - k)
        keep &= (df["speed_mean"].to_numpy() >= min_v) & (df["sleeper_amp"].to_numpy() > 0)
        df = df[keep]
        df.insert(0, "run_id", run_id)
        frames.append(df[out_cols])
    if not frames:
        return pd.DataFrame({c: pd.Series(dtype=object if c == "wheel" else float) for c in out_cols})
    return pd.concat(frames, ignore_index=True)
