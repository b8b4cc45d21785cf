"""A background loop of a worker process: a daemon thread calling one step until stopped.

The webhook deliveries (:mod:`worker.deliveries`) and the retention sweep
(:mod:`worker.background`) are such loops; a loop never holds up a job: it runs in
its own thread, and an error only costs it one round.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable

__all__ = ["PeriodicLoop"]

log = logging.getLogger(__name__)


class PeriodicLoop(threading.Thread):
    """Daemon thread calling ``step()`` until :meth:`stop`; it pauses ``interval_s`` after a
    round that found nothing to do (``step`` returned False) or failed."""

    def __init__(self, name: str, step: Callable[[], bool], interval_s: float) -> None:
        super().__init__(name=name, daemon=True)
        self._step, self.interval_s = step, interval_s
        self._stop_event = threading.Event()

    def stop(self, timeout: float | None = None) -> None:
        """Ask the loop to end and wait for it (``timeout`` s at most)."""
        self._stop_event.set()
        if self.is_alive():
            self.join(timeout)

    @property
    def stopping(self) -> bool:
        """Whether :meth:`stop` was called."""
        return self._stop_event.is_set()

    def run(self) -> None:
        while not self._stop_event.is_set():
            try:
                busy = bool(self._step())
            except Exception as exc:  # noqa: BLE001 - database away, receiver odd: next round
                log.warning("%s: %s", self.name, exc)
                busy = False
            if not busy:
                self._stop_event.wait(self.interval_s)
