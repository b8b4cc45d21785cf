"""A run's metadata: compared with the metadata of a re-upload, corrected by ``PATCH /runs/{id}``.

A run is its file (sha256) plus its metadata. The same file uploaded again with the same (or no)
metadata is the same run (200). With other metadata the upload is refused (409 naming the fields
that differ), because silently keeping either version would lose information; the run's
metadata are corrected explicitly instead: ``PATCH /runs/{id}`` re-ingests the run's canonical
file with the corrected fields into a new file revision (so no worker keeps using a cached copy
of the old one), updates the run, queues a reprocessing job with the run's latest settings and
writes an audit entry with every changed field's old and new value. The results of the old
metadata stay visible until that job is done, then are replaced in one transaction.
"""

from __future__ import annotations

import contextlib
import logging
from collections.abc import Mapping
from typing import Any

from app.audit import record
from app.core.errors import ApiError, not_found
from app.core.i18n import _
from app.core.jsonable import finite_or_none
from app.core.runstore import RunStore
from app.core.security import Actor
from app.db import crud
from app.db.models import Run
from app.db.session import Database
from app.io import RunSummary, ingest, parse_metadata
from app.runs.jobs import settings_from_request

__all__ = ["metadata_differences", "describe_differences", "run_fields", "revise_run_metadata",
           "RevisionOutcome"]

log = logging.getLogger(__name__)


def metadata_differences(stored: Mapping[str, Any], given: Mapping[str, Any]) -> dict[str, tuple[Any, Any]]:
    """Fields of ``given`` whose validated value differs from the ``stored`` metadata.

    Parameters
    ----------
    stored : mapping
        A run's metadata as stored (``RunMetadata.model_dump(mode="json")``).
    given : mapping
        Metadata fields given with a re-upload or a correction (partial; given keys win).

    Returns
    -------
    dict
        Field → (stored value, given value after validation, as JSON), in the order given.
        Values are compared validated: ``"12.5"`` equals ``12.5``, two times of the same
        instant are equal.

    Raises
    ------
    ApiError
        422 naming the metadata field when the merged metadata are invalid.
    """
    new = parse_metadata({**stored, **given})  # RunFileError: 422 naming the field
    old = parse_metadata(stored)
    old_json, new_json = old.model_dump(mode="json"), new.model_dump(mode="json")
    return {k: (old_json.get(k, stored.get(k)), new_json.get(k))
            for k in given if getattr(new, k, new_json.get(k)) != getattr(old, k, old_json.get(k))}


def describe_differences(diffs: Mapping[str, tuple[Any, Any]]) -> str:
    """``"line_id: 'SIM' stored, '4010' given; km_start: ..."``."""
    return "; ".join(f"{k}: {old!r} stored, {new!r} given" for k, (old, new) in diffs.items())


def run_fields(summary: RunSummary) -> dict[str, Any]:
    """The columns of a run that come from its validated file and metadata."""
    md = summary.metadata
    return {
        "vehicle_id": md.vehicle_id, "line_id": md.line_id, "track": md.track,
        "direction": md.direction, "start_time": md.start_time, "km_start": md.km_start,
        "km_increasing": md.km_increasing, "fs": float(summary.fs),
        "n_samples": int(summary.n_samples), "duration_s": float(summary.duration_s),
        "distance_m": finite_or_none(summary.distance_m), "speed_min": finite_or_none(summary.speed_min),
        "speed_max": finite_or_none(summary.speed_max), "channels": list(summary.channels),
        "meta": md.model_dump(mode="json"),
    }


class RevisionOutcome:
    """What a metadata correction did: the changed fields and the queued job (None: no change)."""

    def __init__(self, changed: dict[str, tuple[Any, Any]], job_id: int | None) -> None:
        self.changed = changed
        self.job_id = job_id


def _check_no_active_job(session, run_id: int) -> None:
    active = crud.active_job(session, run_id)
    if active is not None:
        raise ApiError(409, "job", _("run {run_id} has job {id} {status}; cancel it or wait for it before correcting the metadata", run_id=run_id, id=active.id, status=active.status))


def revise_run_metadata(db: Database, store: RunStore, run_id: int, given: Mapping[str, Any],
                        actor: Actor) -> RevisionOutcome:
    """Correct a run's metadata: re-ingest, update, audit and queue its reprocessing.

    Runs in a worker thread (file work). Nothing changes when the given fields equal the
    stored ones.

    Raises
    ------
    ApiError
        404 unknown run, 409 while a job of the run is queued or running, 422 naming the
        field for invalid metadata (nothing written then).
    """
    if not given:
        raise ApiError(422, "metadata", _("give at least one metadata field to change"))
    with db.read() as session:
        run = crud.get_run(session, run_id)
        if run is None:
            raise not_found("run", run_id)
        _check_no_active_job(session, run_id)
        stored, old_relative = dict(run.meta or {}), run.file_path
    changed = metadata_differences(stored, given)
    if not changed:
        return RevisionOutcome({}, None)
    new_relative = store.revised_run_file(old_relative)
    new_path = store.resolve(new_relative)
    summary = ingest(store.local_file(old_relative), "hdf5",
                     {k: new for k, (_, new) in changed.items()}, new_path)  # RunFileError: 422
    try:
        with db.write() as session:
            run = session.get(Run, run_id, with_for_update=True)
            if run is None:
                raise not_found("run", run_id)
            _check_no_active_job(session, run_id)
            for name, value in run_fields(summary).items():
                setattr(run, name, value)
            run.file_path = new_relative
            latest = crud.latest_job(session, run_id)
            settings = settings_from_request(latest.settings if latest else None, {})
            job = crud.create_job(session, run_id, settings.to_dict(), actor.name)
            record(session, actor, "run.metadata", target=run_id, detail={
                "changed": {k: [old, new] for k, (old, new) in changed.items()},
                "job_id": job.id, "file": new_relative, "previous_file": old_relative,
            })
            store.publish_file(new_relative)  # before the job is visible to any worker
            job_id = job.id
    except BaseException:
        new_path.unlink(missing_ok=True)
        raise
    with contextlib.suppress(OSError, ValueError):
        store.resolve(old_relative).unlink(missing_ok=True)
    log.info("run %s metadata corrected (%s); job %s queued", run_id, ", ".join(changed), job_id)
    return RevisionOutcome(changed, job_id)
