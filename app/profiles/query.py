"""A profile query checked against the run's stored results: which job, bin length and wheels,
the indicator columns asked for, the aggregation level, the stiffness index's curves.

Errors name the parameter: 404 (run, wheel), 409 (no results yet), 410 (the 25 cm rows were
swept by retention), 422 (columns, level, max_points).
"""

from __future__ import annotations

from dataclasses import dataclass
from datetime import datetime

from app.analytics.stiffness_index import IndexContext, index_context
from app.core.errors import ApiError
from app.core.i18n import _
from app.core.profile_schema import STEP_COLUMN
from app.db import crud, results_reader
from app.db.display_arrays import DisplayArrays
from app.db.models import PROFILE_VALUE_COLUMNS
from app.db.session import Database
from app.profiles.encoding import etag
from app.runs.lookup import run_with_results
from app.settings import Settings

__all__ = ["AGGREGATED_COLUMNS", "ProfileQuery", "indicator_columns", "results_context", "level_ratio",
           "run_index_context", "profile_query"]

#: Columns aggregated to 1 / 10 / 100 m segments (mean, max, p95 of each).
AGGREGATED_COLUMNS: tuple[str, ...] = tuple(c for c in PROFILE_VALUE_COLUMNS if c != "n_samples")


@dataclass(frozen=True)
class ProfileQuery:
    """A checked profile query of one published job (what :func:`app.profiles.answer.profile_body` answers).

    ``k``: the level in bins (1: the stored bins); ``values``: the indicator columns (None: all);
    ``etag``: the answer's entity tag (the job and the normalised query); ``steps_stored``: whether the
    job stored the step estimate ``sleeper_step`` (None: not asked for).
    """

    run_id: int
    job_id: int
    bin_length: float
    k: int
    wheel: str
    km_from: float | None
    km_to: float | None
    level: float
    max_points: int | None
    values: tuple[str, ...] | None
    layout: str
    index: IndexContext | None = None
    etag: str = ""
    steps_stored: bool | None = None


def indicator_columns(value: str | None, max_points: int | None) -> tuple[str, ...] | None:
    """The asked indicator columns (422 naming the unknown ones); sleeper_amp added for decimation."""
    if value is None:
        return None
    names = [c.strip() for c in value.split(",") if c.strip()]
    if not names:
        raise ApiError(422, "columns", _("names no column"))
    if max_points is not None and "sleeper_amp" not in names:
        names.append("sleeper_amp")  # decimation keeps the peaks of the sleeper amplitude
    try:
        return results_reader.profile_columns(names)[3:]
    except ValueError as exc:
        raise ApiError(422, "columns", exc.args[0] if exc.args and isinstance(exc.args[0], str) else str(exc)) from None


def run_index_context(db: Database, settings: Settings, run_id: int, bin_length: float) -> IndexContext:
    """The reference curves of the run's line for the ``index`` columns."""
    with db.read() as session:
        run = crud.get_run(session, run_id)
        line_id, track = (run.line_id, run.track) if run is not None else (None, None)
    return index_context(db, settings, line_id, track, bin_length)


def _swept(run_id: int, swept_at: datetime) -> ApiError:
    """410: the run's 25 cm rows were removed by the retention sweep."""
    return ApiError(410, "profile", _("the 25 cm rows of run {run_id} were removed by the retention sweep on {date} (TRACKVKF_PROFILE_RETENTION_DAYS); its 10 m / 100 m condition rows remain: GET /api/v1/condition/…", run_id=run_id, date=swept_at.date().isoformat()))


def results_context(
    db: Database, run_id: int, wheel: str | None, arrays: DisplayArrays | None = None
) -> tuple[int, float, list[str]]:
    """Job id and bin length of the stored results and the wheels; 404/409 if none, 410 when swept.

    With the process' ``arrays`` one query (the job shown and whether the run
    was swept) where the run has results.
    """
    with db.read() as session:
        shown = results_reader.results_job_and_sweep(session, run_id) if arrays is not None else None
        if shown is not None and arrays is not None:
            job_id, swept_at = shown
            if swept_at is not None:
                raise _swept(run_id, swept_at)
            bin_length, stored = arrays.job_layout(session, job_id)
            wheels = list(stored)
        else:
            run, job = run_with_results(session, run_id)
            if run.profiles_swept_at is not None:
                raise _swept(run_id, run.profiles_swept_at)
            job_id, bin_length = job.id, results_reader.bin_length_of(job)
            wheels = results_reader.stored_profile_wheels(session, job.id)
    if wheel is not None and wheel not in wheels:
        raise ApiError(
            404, "wheel", _("run {run_id} has no profile for wheel {wheel} (wheels: {wheels})", run_id=run_id, wheel=repr(wheel), wheels=', '.join(wheels))
        )
    return job_id, bin_length, wheels


def level_ratio(level_m: float, bin_length: float) -> int:
    """The aggregation level in bins; 422 naming ``level`` unless a positive multiple of the bin length."""
    ratio = level_m / bin_length
    k = round(ratio)
    if k < 1 or abs(ratio - k) > 1e-9 * max(ratio, 1.0):
        raise ApiError(
            422, "level", _("must be a positive multiple of the bin length {bin_length} m, got {level_m}", bin_length=bin_length, level_m=level_m)
        )
    return int(k)


def profile_query(db: Database, settings: Settings, arrays: DisplayArrays | None, run_id: int, *, wheel: str,
                  km_from: float | None, km_to: float | None, level: float, max_points: int | None,
                  columns: str | None, layout: str, index: bool) -> ProfileQuery:
    """The checked query of ``GET /runs/{id}/profile`` with its ETag (km bounds checked by the caller).

    Runs in a worker thread (database reads; with ``index`` possibly the line's reference curves).
    """
    values = indicator_columns(columns, max_points)
    if index and values is not None:
        values = tuple(dict.fromkeys([*values, "speed_mean", "sleeper_amp"]))
    job_id, bin_length, _arrays = results_context(db, run_id, wheel, arrays)
    steps_stored = None
    if values is None or STEP_COLUMN in values:  # an older job's rows hold no step estimate: the answer says so
        with db.read() as session:
            steps_stored = results_reader.job_stored_steps(session, job_id)
    ctx = run_index_context(db, settings, run_id, bin_length) if index else None
    k = level_ratio(level, bin_length)
    if max_points is not None and max_points > settings.max_profile_rows:
        raise ApiError(422, "max_points", _("must be <= {max_profile_rows}", max_profile_rows=settings.max_profile_rows))
    tag = etag(job_id, settings.max_profile_rows, wheel=wheel, km_from=km_from, km_to=km_to, level=level,
               max_points=max_points, columns=values, layout=layout,
               index=ctx.version() if ctx is not None else None)
    return ProfileQuery(run_id, job_id, bin_length, k, wheel, km_from, km_to, level, max_points, values, layout,
                        ctx, tag, steps_stored)
