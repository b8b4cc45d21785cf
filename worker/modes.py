"""The one choice between the two ways of running the pipeline (``trackvkf worker``, ``python -m worker``).

The database URL picks the mode: SQLite → the local job loop
(:mod:`worker.runner`); PostgreSQL → Procrastinate workers
(:mod:`worker.tasks`, hosted by :mod:`worker.hosting`), unless ``local`` asks for the local loop.
"""

from __future__ import annotations

from app.settings import Settings

__all__ = ["run"]


def run(
    settings: Settings,
    *,
    local: bool = False,
    once: bool = False,
    exit_when_idle: bool = False,
    processes: int = 1,
) -> int:
    """Run the worker of ``settings``' mode until stopped; returns the exit status.

    Parameters
    ----------
    settings : Settings
        Service settings; ``database_url`` picks the mode.
    local : bool
        Use the local job loop even on PostgreSQL (one machine).
    once : bool
        Local mode: exit after one job.
    exit_when_idle : bool
        Exit when no job is queued.
    processes : int
        PostgreSQL mode: worker processes to run (0 = one per core).

    Returns
    -------
    int
        0 after a normal stop, 130 after Ctrl-C, else the workers' status.
    """
    try:
        if settings.is_sqlite or local:
            from worker.runner import run_worker

            run_worker(settings, once=once, exit_when_idle=exit_when_idle)
            return 0
        from worker.hosting import run_worker_process, run_workers

        if exit_when_idle:
            return run_worker_process(settings, wait=False)
        return run_workers(settings, processes)
    except KeyboardInterrupt:
        return 130
