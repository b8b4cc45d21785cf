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
import multiprocessing
import os
import signal
import socket
import threading
import time
import traceback
import uuid
from collections.abc import Callable
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass
from pathlib import Path
from typing import Any

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


def _pool_process_chunk(run_path: Path, settings: ProcessingSettings, chunk: Any, out: Path) -> None:
    """Run one chunk in a pool process; stops when the shared cancel event is set."""
    from worker.pipeline import process_chunk

    process_chunk(run_path, settings, chunk, out, should_cancel=_POOL_CANCEL.is_set)


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
        self.store = RunStore(settings.run_store, settings.shared_store)
        self.worker_id = worker_id or new_worker_id()
        self._stop = threading.Event()
        self._pool: ProcessPoolExecutor | None = None
        self._cancel_event: Any = None

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
        self._close_pool()
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

        failed_chunk: list[int] = []
        try:
            if should_cancel():
                raise PipelineCancelled("cancelled before start")
            settings = ProcessingSettings.from_dict(job.settings)
            run_path = self.store.local_file(run.file_path)
            chunks = plan_chunks(run_path, settings)
            if not queue.record_chunks(
                self.db, job_id, self.worker_id, [(c.index, c.to_dict()) for c in chunks]
            ):
                raise _JobLost
            discard_partial_files(self.store.job_dir(run_id, job_id))
            paths: list[Path] = []
            pending: list[tuple[Any, Path]] = []
            t0 = time.perf_counter()
            for chunk in chunks:
                out = self.store.chunk_path(run_id, job_id, chunk.index)
                paths.append(out)
                if chunk_done(out):
                    self._mark(job_id, chunk.index, ChunkStatus.DONE, out)
                else:
                    pending.append((chunk, out))
            if self.settings.worker_chunk_processes > 1 and len(pending) > 1:
                self._run_parallel(job_id, run_path, settings, pending, should_cancel, failed_chunk)
            else:
                for chunk, out in pending:
                    if should_cancel():
                        raise PipelineCancelled(f"cancelled before chunk {chunk.index}")
                    self._mark(job_id, chunk.index, ChunkStatus.RUNNING)
                    failed_chunk[:] = [chunk.index]
                    process_chunk(run_path, settings, chunk, out, should_cancel=should_cancel)
                    failed_chunk.clear()
                    self._mark(job_id, chunk.index, ChunkStatus.DONE, out)
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
        except _JobLost:
            return self._lost(job_id, run_id)
        except PipelineCancelled:
            return self._cancelled(job_id, run_id, lease)
        except Exception as exc:  # noqa: BLE001 - any error fails the job with its text
            if lease.lost:
                return self._lost(job_id, run_id)
            if self._stop.is_set() and not lease.cancel_requested:
                log.warning("job %s interrupted by shutdown (%s): back to the queue", job_id, exc)
                queue.release_job(self.db, job_id, self.worker_id)
                return JobOutcome(job_id, "requeued")
            log.error("job %s failed:\n%s", job_id, traceback.format_exc())
            for index in failed_chunk:
                try:
                    queue.mark_chunk(self.db, job_id, self.worker_id, index, ChunkStatus.FAILED)
                except Exception:  # noqa: BLE001
                    log.exception("cannot mark chunk %s failed", index)
            error = f"{type(exc).__name__}: {exc}"
            queue.finish_job(self.db, job_id, self.worker_id, JobStatus.FAILED, error[:4000])
            return JobOutcome(job_id, JobStatus.FAILED)
        finally:
            lease.stop()

    def _mark(self, job_id: int, index: int, status: str, out: Path | None = None) -> float:
        """Record a chunk's status; raises :class:`_JobLost` if the job is not ours any more."""
        progress = queue.mark_chunk(
            self.db, job_id, self.worker_id, index, status,
            relative_to_store(self.store, out) if out is not None else None,
        )
        if progress is None:
            raise _JobLost
        if status == ChunkStatus.DONE:
            log.debug("job %s chunk %s done (%.0f %%)", job_id, index, 100 * progress)
        return progress

    def _ensure_pool(self) -> tuple[ProcessPoolExecutor, Any]:
        if self._pool is None:
            if "forkserver" in multiprocessing.get_all_start_methods():
                ctx = multiprocessing.get_context("forkserver")
                # pool processes fork from a server that has the pipeline imported
                ctx.set_forkserver_preload(["worker.runner", "worker.pipeline"])
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
        job_id: int,
        run_path: Path,
        settings: ProcessingSettings,
        pending: list[tuple[Any, Path]],
        should_cancel: Callable[[], bool],
        failed_chunk: list[int],
    ) -> None:
        """Process chunks in a pool of ``worker_chunk_processes`` processes.

        At most one chunk per process is in flight, so a cancel or a loss of
        the job stops the work at the next sub-block of the running chunks.
        """
        pool, cancel = self._ensure_pool()
        cancel.clear()
        todo = list(pending)
        running: dict[Future, Any] = {}
        error: BaseException | None = None

        def submit() -> None:
            chunk, out = todo.pop(0)
            self._mark(job_id, chunk.index, ChunkStatus.RUNNING)
            running[pool.submit(_pool_process_chunk, run_path, settings, chunk, out)] = (chunk, out)

        try:
            while todo and len(running) < self.settings.worker_chunk_processes:
                submit()
            while running:
                done, _ = wait(list(running), timeout=0.2, return_when=FIRST_COMPLETED)
                if should_cancel():
                    cancel.set()
                for future in done:
                    chunk, out = running.pop(future)
                    exc = future.exception()
                    if exc is not None:
                        if error is None:
                            error = exc
                            failed_chunk[:] = [chunk.index]
                        cancel.set()
                        continue
                    self._mark(job_id, chunk.index, ChunkStatus.DONE, out)
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
            from worker.pipeline import PipelineCancelled

            raise PipelineCancelled("cancelled between chunks")

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
