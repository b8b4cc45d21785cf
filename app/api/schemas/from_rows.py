"""Response models built from the services' views of runs and jobs (:mod:`app.runs.catalog`): a
job, a run in a list, a run's detail (with links)."""

from __future__ import annotations

from app.analysis.settings import ProcessingSettings
from app.analysis.units import KMH_PER_MPS
from app.api.schemas.jobs import JobOut
from app.api.schemas.runs import RunDetail, RunOut, RunSummaryOut
from app.core.config import API_PREFIX
from app.core.i18n import DEFAULT_LANGUAGE, restored_message, translate
from app.runs.catalog import JobView, RunView
from app.runs.jobs import job_error

__all__ = ["job_out", "run_out", "run_detail"]


def _settings_shown(stored: dict | None) -> dict:
    """A job's stored settings with every key, the ones it predates at their legacy values."""
    try:
        return ProcessingSettings.from_stored(stored).to_dict()
    except (TypeError, ValueError):
        return dict(stored or {})


def job_out(view: JobView, lang: str = DEFAULT_LANGUAGE) -> JobOut:
    """Response model of a job (its error in ``lang`` where it was kept as a message)."""
    job = view.job
    return JobOut(
        id=job.id,
        run_id=job.run_id,
        status=job.status,
        progress=float(job.progress or 0.0),
        error=job_error(job.error, job.meta, lang),
        settings=_settings_shown(job.settings),
        meta=job.meta,
        warnings=[str(w) for w in (job.meta or {}).get("warnings") or []],
        n_chunks=job.n_chunks,
        chunks_done=view.chunks_done,
        attempts=int(job.attempts or 0),
        cancel_requested=bool(job.cancel_requested),
        created_by=job.created_by,
        created_at=job.created_at,
        started_at=job.started_at,
        finished_at=job.finished_at,
    )


def _kmh(speed_mps: float | None) -> float | None:
    """A stored speed (m/s) as the API answers speeds: km/h."""
    return None if speed_mps is None else speed_mps * KMH_PER_MPS


def _links(run_id: int) -> dict[str, str]:
    base = f"{API_PREFIX}/runs/{run_id}"
    return {
        "self": base,
        "jobs": f"{base}/jobs",
        "profile": f"{base}/profile",
        "profile_csv": f"{base}/profile.csv",
        "profile_parquet": f"{base}/profile.parquet",
        "wheels": f"{base}/wheels",
    }


def _warnings(report: dict, lang: str) -> list[str]:
    """The ingest warnings of a run in ``lang`` (kept as messages since they were; older runs: as stored)."""
    kept = report.get("warning_messages")
    if isinstance(kept, list) and len(kept) == len(report.get("warnings") or []):
        return [translate(restored_message(m), lang) for m in kept]
    return [str(w) for w in report.get("warnings") or []]


def run_out(view: RunView, lang: str = DEFAULT_LANGUAGE) -> RunOut:
    """Response model of a run in a list."""
    run = view.run
    return RunOut(
        id=run.id,
        sha256=run.sha256,
        source_format=run.source_format,
        original_filename=run.original_filename,
        size_bytes=run.size_bytes,
        vehicle_id=run.vehicle_id,
        line_id=run.line_id,
        track=run.track,
        direction=run.direction,
        start_time=run.start_time,
        km_start=run.km_start,
        km_increasing=run.km_increasing,
        created_by=run.created_by,
        created_at=run.created_at,
        summary=RunSummaryOut(
            fs=run.fs,
            n_samples=run.n_samples,
            duration_s=run.duration_s,
            distance_m=run.distance_m,
            speed_min_kmh=_kmh(run.speed_min),
            speed_max_kmh=_kmh(run.speed_max),
            channels=list(run.channels or []),
        ),
        latest_job=job_out(view.latest, lang) if view.latest is not None else None,
        links=_links(run.id),
        warnings=_warnings(run.ingest_report or {}, lang),
    )


def run_detail(view: RunView, lang: str = DEFAULT_LANGUAGE) -> RunDetail:
    """Response model of one run with its metadata."""
    run = view.run
    base = run_out(view, lang)
    return RunDetail(
        **base.model_dump(),
        metadata=dict(run.meta or {}),
        ingest_report=dict((run.ingest_report or {}).get("report", {})),
    )
