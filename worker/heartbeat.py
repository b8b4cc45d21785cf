"""The liveness heartbeat of a worker process (both worker modes).

A daemon thread beside the jobs (:class:`worker.background.Background`) keeps
the process's row of ``worker_heartbeats`` fresh every quarter of
``worker_stale_after_s`` and removes it when the worker stops; ``/health``
counts the rows younger than ``worker_stale_after_s`` as the workers alive
(:mod:`app.operations.liveness`). A worker killed without stopping leaves its
row to go stale, so the health check turns ``degraded`` once jobs wait.
"""

from __future__ import annotations

import logging
import os
import socket
import uuid

from app.db.session import Database
from app.operations import liveness
from app.settings import Settings
from worker.loops import PeriodicLoop

__all__ = ["HeartbeatLoop", "interval_s"]

log = logging.getLogger(__name__)


def interval_s(settings: Settings) -> float:
    """Seconds between two heartbeats: a quarter of ``worker_stale_after_s``."""
    return settings.worker_stale_after_s / 4


class HeartbeatLoop(PeriodicLoop):
    """Daemon thread refreshing this worker process's heartbeat row.

    Parameters
    ----------
    settings : Settings
    db : Database
    mode : str
        ``local`` (the local job loop) or ``procrastinate``.
    """

    def __init__(self, settings: Settings, db: Database, mode: str) -> None:
        self.db, self.mode = db, mode
        self.host, self.pid = socket.gethostname(), os.getpid()
        self.worker_id = f"{self.host}:{self.pid}:{uuid.uuid4().hex[:8]}"
        super().__init__("worker-heartbeat", self._beat, interval_s(settings))

    def _beat(self) -> bool:
        liveness.beat(self.db, self.worker_id, host=self.host, pid=self.pid, mode=self.mode)
        return False  # pause a whole interval

    def start(self) -> None:
        """Beat once now (the worker shows as alive at once), prune long-dead rows, then keep beating."""
        try:
            self._beat()
            pruned = liveness.prune(self.db)
            if pruned:
                log.info("removed the heartbeat rows of %d worker(s) silent for over a day", pruned)
        except Exception as exc:  # noqa: BLE001 - the loop retries; a job must not wait for it
            log.warning("worker heartbeat: %s", exc)
        super().start()

    def stop(self, timeout: float | None = None) -> None:
        """End the loop and remove this worker's row (it stopped: not a lost worker)."""
        super().stop(timeout)
        try:
            liveness.forget(self.db, self.worker_id)
        except Exception as exc:  # noqa: BLE001 - the row goes stale instead
            log.warning("cannot remove the heartbeat of %s: %s", self.worker_id, exc)
