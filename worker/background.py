"""Background loops of a worker process (both worker modes): webhook deliveries, the
retention sweep of 25 cm rows, the liveness heartbeat and the places follow-up (runs whose
places update a killed worker left or a failure put off: :mod:`app.places.followup`; its
first round, at the worker's start, is part of the start-up sweep), each a daemon thread
beside the jobs; and, once at start, the sweep of leftover job folders (:mod:`worker.startup_sweep`).

:func:`start_background` starts them for a worker process; its :meth:`Background.stop`
ends them when the worker stops. A loop never holds up a job: it runs in its own
thread with its own database connections, and an error only costs it one round.
"""

from __future__ import annotations

import datetime as dt
import logging

from app.db.models import utcnow
from app.db.retention import sweep_profiles
from app.db.session import Database
from app.settings import Settings
from worker.deliveries import DeliveryLoop
from worker.heartbeat import HeartbeatLoop
from worker.loops import PeriodicLoop

__all__ = ["Background", "start_background", "sweep_step", "places_step"]

log = logging.getLogger(__name__)


def sweep_step(db: Database, settings: Settings) -> bool:
    """One retention sweep of the 25 cm rows older than ``profile_retention_days`` (False: nothing to keep going)."""
    if settings.profile_retention_days is None:
        return False
    cutoff = utcnow() - dt.timedelta(days=settings.profile_retention_days)
    result = sweep_profiles(db, cutoff)
    if result.runs or result.partitions:
        log.info("retention: 25 cm rows of %d run(s) removed (%d rows, partitions %s) in %.1f s",
                 result.runs, result.rows, result.partitions, result.seconds)
    return False


def places_step(db: Database, settings: Settings) -> bool:
    """One round of the places follow-up: every due run's places update, each line's runs in order
    (True: some were due, look again at once)."""
    from app.places.config import PlacesConfig
    from app.places.followup import FollowupPolicy, run_pending

    policy = FollowupPolicy.from_settings(settings)
    done = run_pending(db, config=PlacesConfig.from_settings(settings), policy=policy, max_runs=20,
                       min_age_s=policy.grace_s)
    return any(r.outcome in ("applied", "not_applied") for r in done)


class Background:
    """The background loops of one worker process."""

    def __init__(self, settings: Settings, mode: str | None = None) -> None:
        self.settings = settings
        self.db = Database(settings.database_url)
        mode = mode or ("local" if settings.is_sqlite else "procrastinate")
        self.loops: list[PeriodicLoop] = [HeartbeatLoop(settings, self.db, mode), DeliveryLoop(settings, self.db),
                                          PeriodicLoop("places-followup", lambda: places_step(self.db, settings),
                                                       settings.places_followup_interval_s)]
        if settings.profile_retention_days is not None:
            self.loops.append(PeriodicLoop("retention-sweep", lambda: sweep_step(self.db, settings),
                                           settings.profile_sweep_interval_s))

    def start(self) -> Background:
        from worker.startup_sweep import sweep_job_folders
        from worker.steps import WorkerRuntime

        try:  # job folders a killed worker left (published, failed): before any job starts
            sweep_job_folders(WorkerRuntime(self.settings, self.db))
        except Exception as exc:  # noqa: BLE001 - clean-up only: the next start retries
            log.warning("start-up sweep of job folders: %s", exc)
        for loop in self.loops:
            loop.start()
        return self

    def stop(self) -> None:
        """Stop every loop (waiting at most the webhook timeout for a send in flight)."""
        for loop in self.loops:
            loop.stop(timeout=self.settings.webhook_timeout_s + 1)
        self.db.dispose()


def start_background(settings: Settings, mode: str | None = None) -> Background:
    """Start the background loops of a worker process (``mode``: ``local`` or ``procrastinate``;
    default: from the database URL)."""
    return Background(settings, mode).start()
