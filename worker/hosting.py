"""Hosting the Procrastinate tasks (:mod:`worker.tasks`): the app on the database, worker
processes and their supervision.

:func:`make_app` binds the task graph's blueprint to an app on ``TRACKVKF_DATABASE_URL``
(PostgreSQL); :func:`run_worker_process` runs one worker (restarted when it stops on its
own, the database restarting), listening for the ``NOTIFY`` of new jobs so they are
planned at once (:func:`_plan_on_notify`) and touching its liveness file; :func:`run_workers`
runs N of them under :class:`worker.supervisor.Supervisor`.

Run a worker with ``trackvkf worker`` (or ``python -m worker``) when
``TRACKVKF_DATABASE_URL`` is a PostgreSQL URL; ``--processes N`` starts N
worker processes (one per core).
"""

from __future__ import annotations

import asyncio
import logging
import os
import signal
from typing import Any

import procrastinate
import psycopg
from procrastinate import exceptions as pexc
from sqlalchemy.engine import make_url

from app.db import crud
from app.settings import Settings, get_settings
from worker.background import start_background
from worker.health import alive_file
from worker.steps import WorkerRuntime
from worker.tasks import (
    PRIORITY_HIGH,
    RUNTIME_KEY,
    TASK_PLAN,
    TRANSIENT_ERRORS,
    blueprint,
    retry_stalled_jobs,
)

__all__ = ["libpq_url", "make_app", "run_worker_process", "run_workers"]

log = logging.getLogger(__name__)


def libpq_url(database_url: str) -> str:
    """The libpq URI (for psycopg/Procrastinate) of a SQLAlchemy PostgreSQL URL.

    Parameters
    ----------
    database_url : str
        ``postgresql+psycopg://user:password@host:port/db`` (any ``postgresql``
        driver suffix).

    Raises
    ------
    ValueError
        If ``database_url`` is not a PostgreSQL URL.
    """
    url = make_url(database_url)
    if url.get_backend_name() != "postgresql":
        raise ValueError(f"database_url: the production mode needs PostgreSQL, got {url.drivername!r}")
    return url.set(drivername="postgresql").render_as_string(hide_password=False)


def make_app(settings: Settings | None = None) -> procrastinate.App:
    """The Procrastinate app of trackvkf with its tasks, for ``settings``' database.

    The tasks of :data:`blueprint` keep their names; :func:`dispatch_jobs`
    runs every 5 s, :func:`retry_stalled_jobs` every third of
    ``worker_stale_after_s`` (1–59 s).

    Parameters
    ----------
    settings : Settings, optional
        Service settings (default: from the environment). ``database_url`` must
        be a PostgreSQL URL; ``worker_stale_after_s`` is the heartbeat age after
        which a worker counts as dead and its jobs are retried.
    """
    settings = settings or get_settings()
    connector = procrastinate.PsycopgConnector(
        conninfo=libpq_url(settings.database_url),
        kwargs={"application_name": "trackvkf-worker"},
        min_size=1,
        max_size=4,
    )
    app = procrastinate.App(connector=connector)
    app.add_tasks_from(blueprint, namespace="")  # no namespace: the names stay trackvkf.*
    stalled_every = max(1, min(59, int(settings.worker_stale_after_s / 3)))
    app.periodic(cron=f"* * * * * */{stalled_every}")(retry_stalled_jobs)
    return app


def run_worker_process(settings: Settings | None = None, *, wait: bool = True) -> int:
    """Run one Procrastinate worker (concurrency 1) in this process until SIGTERM/SIGINT.

    The worker is restarted after a pause when it stops on its own (database
    restarted: its connections and heartbeat fail); jobs it had running are
    retried by :func:`retry_stalled_jobs` if they did not finish.

    Parameters
    ----------
    settings : Settings, optional
    wait : bool
        False: return once the queue is empty (tests, benchmarks).

    Returns
    -------
    int
        Exit status (0 after a graceful stop, 130 after a second signal).
    """
    settings = settings or get_settings()
    background = start_background(settings)  # webhook deliveries, retention sweep: beside the tasks
    try:
        return asyncio.run(_supervise(settings, wait))
    finally:
        background.stop()


async def _supervise(settings: Settings, wait: bool) -> int:
    loop = asyncio.get_running_loop()
    stopping = asyncio.Event()
    current: list[asyncio.Task] = []
    runtimes: list[WorkerRuntime] = []

    def on_signal(signum: int) -> None:
        if stopping.is_set():
            log.warning("second signal %s: exiting now", signum)
            os._exit(130)
        log.info("signal %s: stopping after the running chunk is interrupted", signum)
        stopping.set()
        for rt in runtimes:
            rt.stopping.set()
        for task in current:
            task.cancel()

    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, on_signal, sig)
    options = {
        "concurrency": 1,
        "wait": wait,
        "install_signal_handlers": False,
        "delete_jobs": "successful",
        "update_heartbeat_interval": settings.worker_heartbeat_s,
        "stalled_worker_timeout": settings.worker_stale_after_s,
        "fetch_job_polling_interval": max(settings.worker_poll_interval_s, 0.1),
        "name": f"trackvkf-{os.getpid()}",
    }
    alive = asyncio.create_task(_touch_alive(settings.worker_heartbeat_s), name="alive file")
    try:
        return await _serve(settings, options, stopping, current, runtimes, wait)
    finally:
        alive.cancel()
        alive_file(os.getpid()).unlink(missing_ok=True)


async def _touch_alive(interval_s: float) -> None:
    """Touch this process's liveness file (``python -m worker.health``) periodically."""
    path = alive_file(os.getpid())
    while True:
        path.touch()
        await asyncio.sleep(interval_s)


async def _serve(
    settings: Settings,
    options: dict[str, Any],
    stopping: asyncio.Event,
    current: list[asyncio.Task],
    runtimes: list[WorkerRuntime],
    wait: bool,
) -> int:
    while not stopping.is_set():
        app = make_app(settings)
        rt = WorkerRuntime(settings)
        runtimes[:] = [rt]
        try:
            async with app.open_async():
                task = asyncio.create_task(
                    app.run_worker_async(**options, additional_context={RUNTIME_KEY: rt})
                )
                current[:] = [task]
                listener = asyncio.create_task(_plan_on_notify(app, settings), name="job notifications")
                try:
                    await task
                finally:
                    listener.cancel()
            if not wait:
                break
            log.warning("procrastinate worker stopped on its own; restarting in 1 s")
        except asyncio.CancelledError:
            if stopping.is_set():
                break
            raise
        except (*TRANSIENT_ERRORS, OSError) as exc:  # database away: try again shortly
            log.warning("procrastinate worker failed (%s: %s); restarting in 1 s", type(exc).__name__, exc)
        finally:
            current.clear()
            rt.close()
        try:
            await asyncio.wait_for(stopping.wait(), timeout=1.0)
        except TimeoutError:
            pass
    return 0


async def _plan_on_notify(app: procrastinate.App, settings: Settings) -> None:
    """Defer :func:`plan_job` as soon as a job is queued (PostgreSQL ``NOTIFY``
    :data:`app.db.crud.JOBS_CHANNEL`, sent by the job's commit).

    Every worker process listens; the queueing lock keeps one waiting plan task
    per job and a second planner finds the job claimed. The periodic
    dispatcher stays the fallback (a notification missed while a listener
    reconnects), so a lost notification delays a job by seconds, never loses it.
    """
    while True:
        try:
            conn = await psycopg.AsyncConnection.connect(libpq_url(settings.database_url), autocommit=True)
            async with conn:
                await conn.execute(f"LISTEN {crud.JOBS_CHANNEL}")
                async for note in conn.notifies():
                    if not note.payload.isdigit():
                        continue
                    try:
                        await app.configure_task(
                            TASK_PLAN, queueing_lock=f"plan:{note.payload}", priority=PRIORITY_HIGH
                        ).defer_async(job_id=int(note.payload))
                    except pexc.AlreadyEnqueued:
                        pass
        except asyncio.CancelledError:
            raise
        except Exception as exc:  # database away: listen again shortly; the dispatcher covers the gap
            log.warning("job notifications: %s: %s; listening again in 1 s", type(exc).__name__, exc)
            await asyncio.sleep(1.0)


def run_workers(settings: Settings | None = None, processes: int = 1) -> int:
    """Run ``processes`` worker processes (0 = one per core) until SIGTERM/SIGINT.

    With one process the worker runs in this process; otherwise this process
    supervises ``python -m worker`` children (:class:`worker.supervisor.Supervisor`):
    a child that dies is replaced after a back-off (1 s, doubling up to 60 s
    while children keep dying young), SIGTERM/SIGINT are forwarded to the
    children and waited for.
    """
    if processes < 0:
        raise ValueError(f"processes must be >= 0, got {processes}")
    n = processes or len(os.sched_getaffinity(0)) or 1
    if n == 1:
        return run_worker_process(settings)
    from worker.supervisor import Supervisor, worker_command

    return Supervisor(worker_command(), n).run()
