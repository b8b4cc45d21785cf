"""The profile rows of the runs of a line, as the analytics read them.

:func:`runs_with_results` lists the runs of a line and track that have
results; :func:`analytics_frame` reads their rows without the run ends
(``edge_trim_m``: filter end transients), bins slower than a minimum speed and
bins without amplitude. The analytics endpoints and the reference curves of the
stiffness index read the same rows through here.
"""

from __future__ import annotations

from collections.abc import Sequence

import pandas as pd
from sqlalchemy import func, select
from sqlalchemy.orm import Session

from app.db import results_reader
from app.db.models import Job, JobStatus, ProfileBin, Run

__all__ = ["ANALYTICS_COLUMNS", "runs_with_results", "analytics_frame"]

#: Columns of :func:`analytics_frame`.
ANALYTICS_COLUMNS: tuple[str, ...] = ("run_id", "wheel", "bin", "km", "speed_mean", "sleeper_amp", "sleeper_force_amp")


def runs_with_results(session: Session, line_id: str, track: str | None) -> list[Run]:
    """Runs of a line (and track, if given) with a done job, by start time (then id)."""
    with_results = select(Job.run_id).where(Job.status == JobStatus.DONE)
    stmt = select(Run).where(Run.line_id == line_id, Run.id.in_(with_results))
    if track is not None:
        stmt = stmt.where(Run.track == track)
    runs = list(session.scalars(stmt).all())
    runs.sort(key=lambda r: (r.start_time is None, r.start_time, r.id))
    return runs


def analytics_frame(
    session: Session,
    runs: Sequence[Run],
    *,
    bin_length_m: float,
    min_speed_kmh: float,
    edge_trim_m: float,
    km_from: float | None = None,
    km_to: float | None = None,
    wheel: str | None = None,
    columns: Sequence[str] = ("speed_mean", "sleeper_amp", "sleeper_force_amp"),
) -> pd.DataFrame:
    """Profile rows of ``runs`` (columns ``run_id, wheel, bin, km`` and ``columns``).

    Left out: the first and last ``edge_trim_m`` of each wheel's profile,
    bins slower than ``min_speed_kmh`` and bins without a positive
    ``sleeper_amp``.
    """
    min_v = min_speed_kmh / 3.6
    values = list(dict.fromkeys(["speed_mean", "sleeper_amp", *columns]))
    out_cols = ["run_id", "wheel", "bin", "km", *values]
    frames = []
    for run in runs:
        job_id = results_reader.results_job_id(session, run.id)
        if job_id is None:
            continue
        ext = session.execute(
            select(ProfileBin.wheel, func.min(ProfileBin.bin), func.max(ProfileBin.bin))
            .where(ProfileBin.job_id == job_id).group_by(ProfileBin.wheel)
        ).all()
        df = results_reader.job_profile_frame(session, job_id, wheel=wheel, km_from=km_from, km_to=km_to,
                                              columns=values)
        if df.empty:
            continue
        lo = df["wheel"].map({w: b0 for w, b0, _ in ext})
        hi = df["wheel"].map({w: b1 for w, _, b1 in ext})
        k = edge_trim_m / bin_length_m
        keep = (df["bin"] >= lo + k) & (df["bin"] <= hi - k)
        keep &= (df["speed_mean"] >= min_v) & (df["sleeper_amp"] > 0)
        df = df[keep]
        df.insert(0, "run_id", run.id)
        frames.append(df[out_cols])
    if not frames:
        return pd.DataFrame({c: pd.Series(dtype=object if c == "wheel" else float) for c in out_cols})
    return pd.concat(frames, ignore_index=True)
