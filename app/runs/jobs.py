"""Processing jobs a request starts or stops: a reprocessing job with its settings, a cancel.

The settings of a new job are the run's latest ones with the request's changes, checked by
:class:`~app.analysis.settings.ProcessingSettings` (422 naming the setting) and by what the
service stores (at most :data:`~app.db.models.N_ORDER_COLUMNS` wheel orders per bin).
"""

from __future__ import annotations

import dataclasses
from typing import Any

from app.analysis.settings import ProcessingSettings, SettingError
from app.audit import record
from app.core.diskspace import is_disk_full
from app.core.errors import ApiError, not_found
from app.core.i18n import Msg, _, restored_message, translate
from app.core.runstore import RunStore
from app.core.security import Actor
from app.db import crud
from app.db.models import N_ORDER_COLUMNS, Job, JobStatus
from app.db.queue import CANCELLED_BY_REQUEST
from app.db.session import Database
from app.io import RunFileError
from app.runs.catalog import JobView, job_views

__all__ = ["JOB_STATUSES", "N_ORDER_COLUMNS", "settings_from_request", "reprocess", "cancel", "job_page", "job_view",
           "failure_message", "job_error"]

#: the states of a job (the pages' words for them: app.web.vocabulary)
JOB_STATUSES: tuple[str, ...] = tuple(JobStatus.ALL)

_SETTING_FIELDS = tuple(f.name for f in dataclasses.fields(ProcessingSettings))


def settings_from_request(base: dict | None, changes: dict) -> ProcessingSettings:
    """Merge ``changes`` onto ``base`` settings and validate them.

    Raises
    ------
    ApiError
        422 naming the offending setting.
    """
    merged = {k: v for k, v in (base or {}).items() if k in _SETTING_FIELDS}
    if base is not None:  # stored settings lacking newer keys mean what they meant then
        try:
            merged = ProcessingSettings.from_stored(merged).to_dict()
        except (ValueError, TypeError):
            pass  # validated with the changes below
    merged.update(changes)
    try:
        settings = ProcessingSettings.from_dict(merged)
    except (ValueError, TypeError) as exc:
        text = str(exc)
        field = next((f for f in _SETTING_FIELDS if text.startswith(f)), "settings")
        message = Msg(exc.message, **exc.params) if isinstance(exc, SettingError) else text
        raise ApiError(422, field, message) from None
    if settings.n_wheel_orders > N_ORDER_COLUMNS:
        raise ApiError(
            422,
            "n_wheel_orders",
            _("the service stores at most {N_ORDER_COLUMNS} wheel orders per bin, got {n_wheel_orders}", N_ORDER_COLUMNS=N_ORDER_COLUMNS, n_wheel_orders=settings.n_wheel_orders),
        )
    return settings


def reprocess(db: Database, run_id: int, changes: dict[str, Any], actor: Actor) -> Job:
    """Queue a new processing job for a run with its latest settings changed by ``changes`` (audited).

    Raises
    ------
    ApiError
        404 without the run, 422 naming a bad setting, 409 while a job of the run is queued or running.
    """
    with db.write() as session:
        if crud.get_run(session, run_id) is None:
            raise not_found("run", run_id)
        latest = crud.latest_job(session, run_id)
        settings = settings_from_request(latest.settings if latest else None, changes)
        active = crud.active_job(session, run_id)
        if active is not None:
            raise ApiError(
                409,
                "job",
                _("run {run_id} already has job {id} {status}; cancel it first", run_id=run_id, id=active.id, status=active.status),
            )
        job = crud.create_job(session, run_id, settings.to_dict(), actor.name)
        record(session, actor, "job.create", target=run_id,
               detail={"job_id": job.id, "settings": changes})
    return job


def cancel(db: Database, store: RunStore, job_id: int, actor: Actor) -> JobView:
    """Cancel a job: a queued one at once (its leftover chunk files removed), a running one at its
    worker's next chunk boundary (audited). The job after the change.

    Raises
    ------
    ApiError
        404 without the job, 409 when it is already done, failed or cancelled.
    """
    with db.write() as session:
        outcome = crud.request_cancel(session, job_id)
        if outcome is None:
            raise not_found("job", job_id)
        job = crud.get_job(session, job_id)
        assert job is not None
        if outcome == "final":
            raise ApiError(409, "job", _("job {job_id} is already {status}", job_id=job_id, status=job.status))
        record(session, actor, "job.cancel", target=job_id, detail={"run_id": job.run_id})
        session.refresh(job)
        (view,) = job_views(session, [job])
    if outcome == "cancelled":
        store.remove_job_files(job.run_id, job_id)
    return view


def job_page(db: Database, *, run_id: int | None = None, status: str | None = None, limit: int = 50,
             offset: int = 0, run_must_exist: bool = False) -> tuple[list[JobView], int]:
    """Jobs, newest first, of one run and/or one status if given, and how many match.

    Raises
    ------
    ApiError
        422 naming ``status`` for an unknown one; 404 naming ``run_id`` when ``run_must_exist``
        and there is no such run.
    """
    if status is not None and status not in JobStatus.ALL:
        raise ApiError(422, "status", _("must be one of {choices}", choices=', '.join(JobStatus.ALL)))
    with db.read() as session:
        if run_must_exist and run_id is not None and crud.get_run(session, run_id) is None:
            raise not_found("run", run_id)
        jobs, total = crud.list_jobs(session, run_id=run_id, status=status, limit=limit, offset=offset)
        return job_views(session, jobs), total


def job_view(db: Database, job_id: int) -> JobView:
    """A job and its done chunks; 404 naming ``job_id``."""
    with db.read() as session:
        job = crud.get_job(session, job_id)
        if job is None:
            raise not_found("job", job_id)
        return job_views(session, [job])[0]


def failure_message(exc: BaseException) -> str:
    """The error text of a failed job: ``<exception type>: <its text>``; a :class:`~app.core.i18n.Msg`
    (the reader's language) where the exception's message is marked (a run file's error names its field)."""
    text = exc.message if isinstance(exc, RunFileError) else exc.args[0] if exc.args else None
    problem: str
    if isinstance(exc, RunFileError) and isinstance(text, Msg):
        problem = _("{field}: {problem}", field=exc.field, problem=text)
    elif isinstance(text, Msg) and len(exc.args) == 1:
        problem = text
    else:
        problem = str(exc)
    error = _("{kind}: {problem}", kind=type(exc).__name__, problem=problem)
    if is_disk_full(exc):
        return _("disk full: the results could not be written ({error}); free space and reprocess", error=error)
    return error


def job_error(error: str | None, meta: dict | None, lang: str) -> str | None:
    """A failed or cancelled job's error text in ``lang``: kept as a message (``meta["error_message"]``,
    :func:`failure_message`) since it was, the cancel's words, else as stored."""
    kept = (meta or {}).get("error_message")
    if error is not None and isinstance(kept, dict):
        return translate(restored_message(kept), lang)
    if error == CANCELLED_BY_REQUEST:
        return Msg(CANCELLED_BY_REQUEST).in_language(lang)
    return error
