"""The start-up sweep of a worker process: job folders that no queued or running job owns.

A job's chunk and wheel files are removed when the job is published, fails or
is cancelled (:func:`worker.steps.discard_job_files`). A worker killed between
the commit that publishes a job and that removal (SIGKILL, power loss) leaves
``<run_store>/<run_id>/jobs/<job_id>/`` behind; so does one killed between a
failure's commit and its clean-up. Nothing would remove it until the run's next
job ends. Every worker process therefore sweeps the store once when it starts
(both worker modes, :class:`worker.background.Background`): for every run with
a ``jobs/`` folder (here and in the shared store), the folders of jobs that are
no longer queued or running go, by the same rule as at a job's end, so a job
that another worker still runs, or that waits in the queue to resume from its
chunks, keeps its files.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field

from worker.steps import WorkerRuntime, discard_job_files

__all__ = ["SweepResult", "runs_with_job_folders", "sweep_job_folders"]

log = logging.getLogger(__name__)


@dataclass
class SweepResult:
    """What a start-up sweep removed.

    Attributes
    ----------
    removed : dict of int to list of int
        Run id → the jobs whose folders were removed.
    runs_checked : int
        Runs that had a ``jobs/`` folder.
    seconds : float
        Wall time of the sweep, s.
    """

    removed: dict[int, list[int]] = field(default_factory=dict)
    runs_checked: int = 0
    seconds: float = 0.0

    @property
    def n_jobs(self) -> int:
        """Number of job folders removed."""
        return sum(len(v) for v in self.removed.values())


def runs_with_job_folders(rt: WorkerRuntime) -> list[int]:
    """Ids of the runs that have a ``jobs/`` folder in the run store (or any run in the shared store)."""
    ids = {run_id for run_id in rt.store.run_ids_on_disk() if (rt.store.run_dir(run_id) / "jobs").is_dir()}
    shared = rt.store.shared
    if shared is not None:
        try:
            names = shared.fs.ls(shared.root, detail=False)
        except FileNotFoundError:
            names = []
        ids |= {int(n) for n in (str(e).rstrip("/").rsplit("/", 1)[-1] for e in names) if n.isdigit()}
    return sorted(ids)


def sweep_job_folders(rt: WorkerRuntime) -> SweepResult:
    """Remove the job folders of every run whose jobs are no longer queued or running.

    Parameters
    ----------
    rt : WorkerRuntime
        The worker process's runtime (database, run store).

    Returns
    -------
    SweepResult
        Never raises for a run that cannot be swept (logged; its folders are
        retried at the next start or at the run's next job end).
    """
    t0 = time.perf_counter()
    result = SweepResult()
    for run_id in runs_with_job_folders(rt):
        result.runs_checked += 1
        gone = discard_job_files(rt, run_id)
        if gone:
            result.removed[run_id] = gone
    result.seconds = time.perf_counter() - t0
    if result.removed:
        log.info("start-up sweep: removed %d leftover job folder(s) of %d run(s) in %.2f s",
                 result.n_jobs, len(result.removed), result.seconds)
    return result
