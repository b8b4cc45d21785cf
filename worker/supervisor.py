"""``trackvkf worker --processes N``: N worker processes, each replaced when it dies.

The supervising process starts ``N`` children (``python -m worker --processes 1``),
restarts one that exits while the worker is not stopping (a crash, SIGKILL,
the kernel's OOM killer) after a back-off that doubles from
``min_backoff_s`` to ``max_backoff_s`` while the child keeps dying young and
starts again from ``min_backoff_s`` once a child lived ``healthy_after_s``
seconds, and forwards SIGTERM/SIGINT to the children (then waits for them).

It records how many children it keeps and which ones run now in
``<tmp>/trackvkf-workers-<pid>.json`` (:func:`status_file`), so that
``python -m worker.health`` reports the real count (a dead child no longer
looks alive for ``worker_stale_after_s``).
"""

from __future__ import annotations

import json
import logging
import os
import signal
import subprocess
import sys
import time
from dataclasses import dataclass, field

from app.core.atomic import atomic_path
from worker.health import alive_file, status_file

__all__ = ["Supervisor", "worker_command"]

log = logging.getLogger(__name__)


def worker_command() -> list[str]:
    """The command of one worker process."""
    return [sys.executable, "-m", "worker", "--processes", "1"]


@dataclass
class _Slot:
    """One child position: its process, when it started, and its restart back-off."""

    proc: subprocess.Popen | None = None
    started: float = 0.0
    backoff_s: float = 0.0
    restart_at: float | None = None
    restarts: int = 0
    codes: list[int] = field(default_factory=list)


class Supervisor:
    """Keep ``n`` child processes running until SIGTERM/SIGINT.

    Parameters
    ----------
    argv : list of str
        Command of a child.
    n : int
        Number of children (>= 1).
    min_backoff_s, max_backoff_s : float
        Pause before the restart of a child that died: ``min_backoff_s``
        first, doubled at each death of a child that lived less than
        ``healthy_after_s``, at most ``max_backoff_s`` (s).
    healthy_after_s : float
        A child that lived this long resets its slot's back-off, s.
    poll_s : float
        Interval at which the children are looked at, s.
    """

    def __init__(
        self,
        argv: list[str],
        n: int,
        *,
        min_backoff_s: float = 1.0,
        max_backoff_s: float = 60.0,
        healthy_after_s: float = 60.0,
        poll_s: float = 0.2,
    ) -> None:
        if n < 1:
            raise ValueError(f"n must be >= 1, got {n}")
        if not 0 < min_backoff_s <= max_backoff_s:
            raise ValueError(
                f"backoff must satisfy 0 < min_backoff_s <= max_backoff_s, got {min_backoff_s}, {max_backoff_s}"
            )
        if healthy_after_s <= 0 or poll_s <= 0:
            raise ValueError("healthy_after_s and poll_s must be > 0 s")
        self.argv = list(argv)
        self.slots = [_Slot(backoff_s=min_backoff_s) for _ in range(n)]
        self.min_backoff_s, self.max_backoff_s = min_backoff_s, max_backoff_s
        self.healthy_after_s, self.poll_s = healthy_after_s, poll_s
        self.stopping = False
        self._signal: int | None = None
        self._signalled: set[int] = set()

    # --- children ---------------------------------------------------------------
    def _start(self, slot: _Slot) -> None:
        slot.proc = subprocess.Popen(self.argv)
        slot.started = time.monotonic()
        slot.restart_at = None
        log.info("worker process %s started", slot.proc.pid)

    def _reap(self, slot: _Slot, now: float) -> None:
        """A child exited: schedule its restart unless the worker stops."""
        assert slot.proc is not None
        code = slot.proc.returncode
        if self.stopping and code == -(self._signal or 0):
            code = 0  # stopped by the signal forwarded to it (before it could handle it: starting up)
        slot.codes.append(code)
        lived = now - slot.started
        alive_file(slot.proc.pid).unlink(missing_ok=True)  # a killed child leaves it behind
        pid, slot.proc = slot.proc.pid, None
        if self.stopping:
            return
        if lived >= self.healthy_after_s:
            slot.backoff_s = self.min_backoff_s
        slot.restart_at = now + slot.backoff_s
        slot.restarts += 1
        log.warning(
            "worker process %s exited with status %s after %.1f s; starting a new one in %.1f s",
            pid, code, lived, slot.backoff_s,
        )
        slot.backoff_s = min(slot.backoff_s * 2, self.max_backoff_s)

    def _write_status(self) -> None:
        running = [s.proc.pid for s in self.slots if s.proc is not None and s.proc.poll() is None]
        status = {"expected": len(self.slots), "pids": running, "restarts": sum(s.restarts for s in self.slots)}
        with atomic_path(status_file(os.getpid())) as tmp:
            tmp.write_text(json.dumps(status))

    # --- the loop ---------------------------------------------------------------
    def _on_signal(self, signum: int, frame: object) -> None:  # noqa: ARG002
        self.stopping = True
        self._signal = signum
        self._forward(signum)

    def _forward(self, signum: int) -> None:
        """Send ``signum`` once to every running child (a second one would abort its chunk)."""
        for slot in self.slots:
            proc = slot.proc
            if proc is not None and proc.poll() is None and proc.pid not in self._signalled:
                self._signalled.add(proc.pid)
                proc.send_signal(signum)

    def run(self) -> int:
        """Supervise until SIGTERM/SIGINT, then wait for the children.

        Returns
        -------
        int
            The largest exit status of the children's last runs (0 after a
            graceful stop).
        """
        previous = {sig: signal.signal(sig, self._on_signal) for sig in (signal.SIGTERM, signal.SIGINT)}
        try:
            for slot in self.slots:
                self._start(slot)
            while not self.stopping:
                now = time.monotonic()
                for slot in self.slots:
                    if slot.proc is not None and slot.proc.poll() is not None:
                        self._reap(slot, now)
                    if slot.proc is None and slot.restart_at is not None and now >= slot.restart_at:
                        self._start(slot)
                self._write_status()
                time.sleep(self.poll_s)
            assert self._signal is not None
            self._forward(self._signal)  # a child started while the signal came
            for slot in self.slots:
                if slot.proc is not None:
                    slot.proc.wait()
                    self._reap(slot, time.monotonic())
        finally:
            for sig, handler in previous.items():
                signal.signal(sig, handler)
            status_file(os.getpid()).unlink(missing_ok=True)
        last = [s.codes[-1] for s in self.slots if s.codes]
        return max((c if c >= 0 else 128 - c for c in last), default=0)
