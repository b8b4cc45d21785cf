"""The local job loop of the embedded mode (SQLite or PostgreSQL, one machine).

A :class:`LocalWorker` claims the oldest queued job (or a job whose worker
died: stale heartbeat), plans its chunks, runs every chunk whose result file
does not exist yet, assembles the results and stores them in one transaction
that replaces the run's previous rows. Killing the worker at any moment and
starting it again finishes the job with the same result: finished chunks are
kept (their files are the proof), unfinished ones are recomputed, and the
rows are written once.

Cancellation (user request), loss of the job (run deleted, job claimed by
another worker) and worker shutdown are noticed by a heartbeat thread and
checked between chunks and, through ``should_cancel``, inside a chunk.
"""

from __future__ import annotations

import logging
import os
import signal
import socket
import threading
import time
import traceback
import uuid
from dataclasses import dataclass
from pathlib import Path

from app.analysis.settings import ProcessingSettings
from app.core.config import Settings
from app.db import crud, queue
from app.db.models import ChunkStatus, JobStatus
from app.db.session import Database
from worker.store import RunStore, chunk_done, discard_partial_files, relative_to_store

__all__ = ["LocalWorker", "JobOutcome", "new_worker_id", "run_worker"]

log = logging.getLogger(__name__)


def new_worker_id() -> str:
    """A unique worker id: ``host:pid:random``."""
    return f"{socket.gethostname()}:{os.getpid()}:{uuid.uuid4().hex[:8]}"


@dataclass(frozen=True)
class JobOutcome:
    """What happened to a claimed job.

    Attributes
    ----------
    job_id : int
    status : str
        ``done``, ``failed``, ``cancelled``, ``requeued`` (worker shutdown) or
        ``lost`` (deleted, or taken over by another worker).
    """

    job_id: int
    status: str


class _Lease(threading.Thread):
    """Heartbeat thread of one job: keeps it claimed, watches for cancel and loss."""

    def __init__(self, db: Database, job_id: int, worker_id: str, interval_s: float) -> None:
        super().__init__(name=f"heartbeat-{job_id}", daemon=True)
        self.db = db
        self.job_id = job_id
        self.worker_id = worker_id
        self.interval_s = interval_s
        self._halt = threading.Event()
        self.lost = False
        self.cancel_requested = False

    def beat(self) -> None:
        try:
            lease = queue.heartbeat(self.db, self.job_id, self.worker_id)
        except Exception as exc:  # noqa: BLE001 - a missed beat is retried
            log.warning("heartbeat of job %s failed: %s", self.job_id, exc)
            return
        if not lease.owned:
            self.lost = True
        if lease.cancel_requested:
            self.cancel_requested = True

    def run(self) -> None:
        while not self._halt.wait(self.interval_s):
            self.beat()

    def stop(self) -> None:
        self._halt.set()
        if self.is_alive():
            self.join(timeout=10)


class LocalWorker:
    """A worker process's job loop.

    Parameters
    ----------
    settings : Settings
        Service settings (database, run store, poll/heartbeat intervals).
    db : Database, optional
        Database to use; created from ``settings.database_url`` if omitted.
    worker_id : str, optional
        Id recorded on claimed jobs; unique by default.
    """

    def __init__(
        self, settings: Settings, *, db: Database | None = None, worker_id: str | None = None
    ) -> None:
        self.settings = settings
        self.db = db or Database(settings.database_url)
        self.store = RunStore(settings.run_store)
        self.worker_id = worker_id or new_worker_id()
        self._stop = threading.Event()

    # --- control ----------------------------------------------------------
    def stop(self) -> None:
        """Ask the loop to stop; a running job is put back in the queue."""
        self._stop.set()

    @property
    def stopping(self) -> bool:
        """Whether :meth:`stop` was called."""
        return self._stop.is_set()

    def run(self, *, once: bool = False, exit_when_idle: bool = False) -> int:
        """Process jobs until stopped.

        Parameters
        ----------
        once : bool
            Return after the first claimed job.
        exit_when_idle : bool
            Return when no job is claimable instead of polling.

        Returns
        -------
        int
            Number of jobs processed (any outcome).
        """
        log.info("worker %s started (database %s)", self.worker_id, self.settings.database_url)
        processed = 0
        while not self._stop.is_set():
            try:
                job_id = queue.claim_next_job(
                    self.db, self.worker_id, self.settings.worker_stale_after_s
                )
            except Exception as exc:  # noqa: BLE001 - database hiccup: retry after a pause
                log.warning("cannot claim a job: %s", exc)
                job_id = None
            if job_id is None:
                if exit_when_idle:
                    break
                self._stop.wait(self.settings.worker_poll_interval_s)
                continue
            outcome = self.process(job_id)
            log.info("job %s %s", outcome.job_id, outcome.status)
            processed += 1
            if once:
                break
        log.info("worker %s stopped after %d job(s)", self.worker_id, processed)
        return processed

    # --- one job ------------------------------------------------------------
    def process(self, job_id: int) -> JobOutcome:
        """Run a job this worker has claimed to completion (or failure/cancel)."""
        from worker.pipeline import PipelineCancelled, assemble, plan_chunks, process_chunk

        with self.db.read() as session:
            job = crud.get_job(session, job_id)
            run = crud.get_run(session, job.run_id) if job is not None else None
        if job is None or run is None:
            return JobOutcome(job_id, "lost")
        run_id = run.id

        lease = _Lease(self.db, job_id, self.worker_id, self.settings.worker_heartbeat_s)
        lease.beat()
        if lease.lost:
            return JobOutcome(job_id, "lost")
        lease.start()

        def should_cancel() -> bool:
            return lease.lost or lease.cancel_requested or self._stop.is_set()

        current_chunk: int | None = None
        try:
            if should_cancel():
                raise PipelineCancelled("cancelled before start")
            settings = ProcessingSettings.from_dict(job.settings)
            run_path = self.store.resolve(run.file_path)
            if not run_path.is_file():
                raise FileNotFoundError(f"run file {run.file_path} is missing from the run store")
            chunks = plan_chunks(run_path, settings)
            if not queue.record_chunks(
                self.db, job_id, self.worker_id, [(c.index, c.to_dict()) for c in chunks]
            ):
                return self._lost(job_id, run_id)
            discard_partial_files(self.store.job_dir(run_id, job_id))
            paths: list[Path] = []
            t0 = time.perf_counter()
            for chunk in chunks:
                out = self.store.chunk_path(run_id, job_id, chunk.index)
                paths.append(out)
                if chunk_done(out):
                    if queue.mark_chunk(
                        self.db, job_id, self.worker_id, chunk.index, ChunkStatus.DONE,
                        relative_to_store(self.store, out),
                    ) is None:
                        return self._lost(job_id, run_id)
                    continue
                if should_cancel():
                    raise PipelineCancelled(f"cancelled before chunk {chunk.index}")
                current_chunk = chunk.index
                if queue.mark_chunk(
                    self.db, job_id, self.worker_id, chunk.index, ChunkStatus.RUNNING
                ) is None:
                    return self._lost(job_id, run_id)
                process_chunk(run_path, settings, chunk, out, should_cancel=should_cancel)
                progress = queue.mark_chunk(
                    self.db, job_id, self.worker_id, chunk.index, ChunkStatus.DONE,
                    relative_to_store(self.store, out),
                )
                current_chunk = None
                if progress is None:
                    return self._lost(job_id, run_id)
                log.debug("job %s chunk %s done (%.0f %%)", job_id, chunk.index, 100 * progress)
            if should_cancel():
                raise PipelineCancelled("cancelled before assembling")
            results = assemble(run_path, settings, paths)
            t_chunks = time.perf_counter() - t0
            meta = dict(results.meta or {})
            meta["worker"] = {
                "worker_id": self.worker_id,
                "n_chunks": len(chunks),
                "compute_s": round(t_chunks, 3),
                "run_sha256": run.sha256,
            }
            stored = queue.complete_job(
                self.db, job_id, self.worker_id, run_id, results.profiles, results.wheels, meta
            )
            if stored:
                return JobOutcome(job_id, JobStatus.DONE)
            lease.beat()
            if lease.cancel_requested and not lease.lost:
                raise PipelineCancelled("cancelled before storing the results")
            return self._lost(job_id, run_id)
        except PipelineCancelled:
            return self._cancelled(job_id, run_id, lease)
        except Exception as exc:  # noqa: BLE001 - any error fails the job with its text
            if lease.lost:
                return self._lost(job_id, run_id)
            log.error("job %s failed:\n%s", job_id, traceback.format_exc())
            if current_chunk is not None:
                try:
                    queue.mark_chunk(
                        self.db, job_id, self.worker_id, current_chunk, ChunkStatus.FAILED
                    )
                except Exception:  # noqa: BLE001
                    log.exception("cannot mark chunk %s failed", current_chunk)
            error = f"{type(exc).__name__}: {exc}"
            queue.finish_job(self.db, job_id, self.worker_id, JobStatus.FAILED, error[:4000])
            return JobOutcome(job_id, JobStatus.FAILED)
        finally:
            lease.stop()

    def _cancelled(self, job_id: int, run_id: int, lease: _Lease) -> JobOutcome:
        if lease.lost:
            return self._lost(job_id, run_id)
        if lease.cancel_requested or not self._stop.is_set():
            queue.finish_job(
                self.db, job_id, self.worker_id, JobStatus.CANCELLED, "cancelled by request"
            )
            return JobOutcome(job_id, JobStatus.CANCELLED)
        queue.release_job(self.db, job_id, self.worker_id)
        return JobOutcome(job_id, "requeued")

    def _lost(self, job_id: int, run_id: int) -> JobOutcome:
        """The job is no longer ours; if its run was deleted, remove leftover files."""
        with self.db.read() as session:
            run_exists = crud.get_run(session, run_id) is not None
        if not run_exists:
            self.store.remove_run(run_id)
        log.warning("job %s was lost (run %s %s)", job_id, run_id, "exists" if run_exists else "deleted")
        return JobOutcome(job_id, "lost")


def run_worker(
    settings: Settings, *, once: bool = False, exit_when_idle: bool = False
) -> int:
    """Run a :class:`LocalWorker` in this process until SIGINT/SIGTERM.

    The first SIGINT or SIGTERM stops the worker gracefully: the running job
    is stopped at its next check and put back in the queue. A second one
    aborts at once (the job is claimed again after its heartbeat goes stale).

    Returns
    -------
    int
        Number of jobs processed.
    """
    worker = LocalWorker(settings)

    def _graceful(signum: int, frame: object) -> None:  # noqa: ARG001
        if worker.stopping:
            raise KeyboardInterrupt
        log.info("signal %s: stopping after the current chunk", signum)
        worker.stop()

    previous = {}
    if threading.current_thread() is threading.main_thread():
        for sig in (signal.SIGINT, signal.SIGTERM):
            previous[sig] = signal.signal(sig, _graceful)
    try:
        return worker.run(once=once, exit_when_idle=exit_when_idle)
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
        worker.db.dispose()
