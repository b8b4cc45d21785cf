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

The job's steps (load, plan, mark, metadata, and its ends: published, failed,
cancelled) and the chunk store are those of the Procrastinate tasks too
(:mod:`worker.steps`, :class:`~worker.chunkstore.ChunkStore`).
"""

from __future__ import annotations

import logging
import multiprocessing
import os
import signal
import socket
import threading
import time
import uuid
from collections.abc import Callable
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from app.analysis.settings import ProcessingSettings
from app.db import queue
from app.db.models import ChunkStatus, JobStatus
from app.db.session import Database
from app.pipeline import ChunkSpec, PipelineCancelled, assemble, process_chunk
from app.settings import Settings
from worker.background import Background
from worker.chunkstore import ChunkStore
from worker.steps import (
    JobRecord,
    WorkerRuntime,
    end_cancelled,
    end_failed,
    end_published,
    job_meta,
    load_job,
    mark_chunk_done,
    record_plan,
    remove_files_if_deleted,
)

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


class _JobLost(Exception):
    """The job is no longer this worker's (cancelled and deleted, or taken over)."""


_POOL_CANCEL: Any = None


def _pool_init(cancel_event: Any) -> None:
    """Initializer of chunk-pool processes: remember the shared cancel event."""
    global _POOL_CANCEL
    _POOL_CANCEL = cancel_event
    # Ctrl-C in a terminal reaches the whole process group: the parent decides
    # (graceful stop sets the cancel event), the pool processes ignore it.
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def _pool_process_chunk(
    chunks: ChunkStore, run_id: int, job_id: int, run_path: Path, settings: ProcessingSettings, chunk: ChunkSpec
) -> None:
    """Run one chunk in a pool process; stops when the shared cancel event is set."""
    chunks.write(
        run_id, job_id, chunk.index,
        lambda out: process_chunk(run_path, settings, chunk, out, should_cancel=_POOL_CANCEL.is_set),
    )


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
        self.runtime = WorkerRuntime(settings, db or Database(settings.database_url))
        self.worker_id = worker_id or new_worker_id()
        self._pool: ProcessPoolExecutor | None = None
        self._cancel_event: Any = None

    @property
    def db(self) -> Database:
        """The worker's database."""
        return self.runtime.db

    # --- control ----------------------------------------------------------
    def stop(self) -> None:
        """Ask the loop to stop; a running job is put back in the queue."""
        self.runtime.stopping.set()

    @property
    def stopping(self) -> bool:
        """Whether :meth:`stop` was called."""
        return self.runtime.stopping.is_set()

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
        while not self.stopping:
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
                self.runtime.stopping.wait(self.settings.worker_poll_interval_s)
                continue
            try:
                outcome = self.process(job_id)
            except Exception:  # noqa: BLE001 - e.g. the database full or away: the worker lives on
                # the job could not even be marked failed; it is claimed again once its heartbeat is stale
                log.exception("job %s: cannot record its outcome; retrying later", job_id)
                processed += 1
                self.runtime.stopping.wait(self.settings.worker_poll_interval_s)
                if once:
                    break
                continue
            log.info("job %s %s", outcome.job_id, outcome.status)
            processed += 1
            if once:
                break
        self._close_pool()
        log.info("worker %s stopped after %d job(s)", self.worker_id, processed)
        return processed

    # --- one job ------------------------------------------------------------
    def process(self, job_id: int) -> JobOutcome:
        """Run a job this worker has claimed to completion (or failure/cancel)."""
        rt = self.runtime
        record = load_job(self.db, job_id)
        if record.lost:
            return JobOutcome(job_id, "lost")
        run_id = record.run.id

        lease = _Lease(self.db, job_id, self.worker_id, self.settings.worker_heartbeat_s)
        lease.beat()
        if lease.lost:
            return JobOutcome(job_id, "lost")
        lease.start()

        def should_cancel() -> bool:
            return lease.lost or lease.cancel_requested or self.stopping

        failed_chunk: list[int] = []
        try:
            if should_cancel():
                raise PipelineCancelled("cancelled before start")
            settings = record.settings
            run_path = record.run_path(rt.store)
            chunks = record_plan(rt, record, run_path, worker_id=self.worker_id)
            if chunks is None:
                raise _JobLost
            pending: list[ChunkSpec] = []
            t0 = time.perf_counter()
            for chunk in chunks:
                if rt.chunks.exists(run_id, job_id, chunk.index):
                    self._mark_done(record, chunk.index)
                else:
                    pending.append(chunk)
            if self.settings.worker_chunk_processes > 1 and len(pending) > 1:
                self._run_parallel(record, run_path, settings, pending, should_cancel, failed_chunk)
            else:
                for chunk in pending:
                    if should_cancel():
                        raise PipelineCancelled(f"cancelled before chunk {chunk.index}")
                    self._mark_running(job_id, chunk.index)
                    failed_chunk[:] = [chunk.index]
                    rt.chunks.write(
                        run_id, job_id, chunk.index,
                        lambda out, c=chunk: process_chunk(run_path, settings, c, out, should_cancel=should_cancel),
                    )
                    failed_chunk.clear()
                    self._mark_done(record, chunk.index)
            if should_cancel():
                raise PipelineCancelled("cancelled before assembling")
            with rt.chunks.local_copies(run_id, job_id, [c.index for c in chunks]) as paths:
                results = assemble(run_path, settings, paths)
            meta = job_meta(settings, len(chunks), worker_id=self.worker_id, run_sha256=record.run.sha256,
                            warnings=results.meta.get("warnings", ()),
                            track_impacts=results.meta.get("track_impacts"), compute_s=time.perf_counter() - t0)
            if end_published(rt, record, results.profiles, results.wheels, meta, worker_id=self.worker_id):
                return JobOutcome(job_id, JobStatus.DONE)
            lease.beat()
            if lease.cancel_requested and not lease.lost:
                raise PipelineCancelled("cancelled before storing the results")
            return self._lost(job_id, run_id)
        except _JobLost:
            return self._lost(job_id, run_id)
        except PipelineCancelled:
            return self._cancelled(job_id, run_id, lease)
        except Exception as exc:  # noqa: BLE001 - any error fails the job with its text
            if lease.lost:
                return self._lost(job_id, run_id)
            if self.stopping and not lease.cancel_requested:
                log.warning("job %s interrupted by shutdown (%s): back to the queue", job_id, exc)
                queue.release_job(self.db, job_id, self.worker_id)
                return JobOutcome(job_id, "requeued")
            for index in failed_chunk:
                try:
                    queue.mark_chunk(self.db, job_id, index, ChunkStatus.FAILED, worker_id=self.worker_id)
                except Exception:  # noqa: BLE001
                    log.exception("cannot mark chunk %s failed", index)
            end_failed(rt, job_id, run_id, exc, worker_id=self.worker_id)
            return JobOutcome(job_id, JobStatus.FAILED)
        finally:
            lease.stop()

    def _mark_running(self, job_id: int, index: int) -> None:
        """Record a chunk as running; raises :class:`_JobLost` if the job is not ours any more."""
        if queue.mark_chunk(self.db, job_id, index, ChunkStatus.RUNNING, worker_id=self.worker_id) is None:
            raise _JobLost

    def _mark_done(self, record: JobRecord, index: int) -> None:
        """Record a chunk as done; raises :class:`_JobLost` if the job is not ours any more."""
        progress = mark_chunk_done(self.runtime, record, index, worker_id=self.worker_id)
        if progress is None:
            raise _JobLost
        log.debug("job %s chunk %s done (%.0f %%)", record.job.id, index, 100 * progress)

    def _ensure_pool(self) -> tuple[ProcessPoolExecutor, Any]:
        if self._pool is None:
            if "forkserver" in multiprocessing.get_all_start_methods():
                ctx = multiprocessing.get_context("forkserver")
                # pool processes fork from a server that has the pipeline imported
                ctx.set_forkserver_preload(["worker.runner", "app.pipeline"])
            else:
                ctx = multiprocessing.get_context("spawn")
            self._cancel_event = ctx.Event()
            self._pool = ProcessPoolExecutor(
                max_workers=self.settings.worker_chunk_processes,
                mp_context=ctx,
                initializer=_pool_init,
                initargs=(self._cancel_event,),
            )
        return self._pool, self._cancel_event

    def _close_pool(self) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
            self._pool = None
            self._cancel_event = None

    def _run_parallel(
        self,
        record: JobRecord,
        run_path: Path,
        settings: ProcessingSettings,
        pending: list[ChunkSpec],
        should_cancel: Callable[[], bool],
        failed_chunk: list[int],
    ) -> None:
        """Process chunks in a pool of ``worker_chunk_processes`` processes.

        At most one chunk per process is in flight, so a cancel or a loss of
        the job stops the work at the next sub-block of the running chunks.
        """
        pool, cancel = self._ensure_pool()
        cancel.clear()
        job_id, run_id = record.job.id, record.run.id
        todo = list(pending)
        running: dict[Future, ChunkSpec] = {}
        error: BaseException | None = None

        def submit() -> None:
            chunk = todo.pop(0)
            self._mark_running(job_id, chunk.index)
            future = pool.submit(_pool_process_chunk, self.runtime.chunks, run_id, job_id, run_path, settings, chunk)
            running[future] = chunk

        try:
            while todo and len(running) < self.settings.worker_chunk_processes:
                submit()
            while running:
                done, _ = wait(list(running), timeout=0.2, return_when=FIRST_COMPLETED)
                if should_cancel():
                    cancel.set()
                for future in done:
                    chunk = running.pop(future)
                    exc = future.exception()
                    if exc is not None:
                        if error is None:
                            error = exc
                            failed_chunk[:] = [chunk.index]
                        cancel.set()
                        continue
                    self._mark_done(record, chunk.index)
                if error is None and not should_cancel():
                    while todo and len(running) < self.settings.worker_chunk_processes:
                        submit()
        except BaseException:
            cancel.set()
            for future in running:
                future.cancel()
            wait(list(running))
            raise
        if error is not None:
            if isinstance(error, BrokenProcessPool):
                self._close_pool()
            raise error
        if todo or should_cancel():
            raise PipelineCancelled("cancelled between chunks")

    def _cancelled(self, job_id: int, run_id: int, lease: _Lease) -> JobOutcome:
        if lease.lost:
            return self._lost(job_id, run_id)
        if lease.cancel_requested or not self.stopping:
            end_cancelled(self.runtime, job_id, run_id, worker_id=self.worker_id)
            return JobOutcome(job_id, JobStatus.CANCELLED)
        queue.release_job(self.db, job_id, self.worker_id)
        return JobOutcome(job_id, "requeued")

    def _lost(self, job_id: int, run_id: int) -> JobOutcome:
        """The job is no longer ours; if its run was deleted, remove leftover files."""
        deleted = remove_files_if_deleted(self.runtime, run_id)
        log.warning("job %s was lost (run %s %s)", job_id, run_id, "deleted" if deleted else "exists")
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
    background = Background(settings, "local")  # webhook deliveries, retention sweep: beside the jobs

    def _graceful(signum: int, frame: object) -> None:  # noqa: ARG001
        if worker.stopping:
            raise KeyboardInterrupt
        log.info("signal %s: stopping after the current chunk", signum)
        worker.stop()

    previous = {}
    if threading.current_thread() is threading.main_thread():
        for sig in (signal.SIGINT, signal.SIGTERM):
            previous[sig] = signal.signal(sig, _graceful)
    background.start()
    try:
        return worker.run(once=once, exit_when_idle=exit_when_idle)
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
        background.stop()
        worker.runtime.close()
