"""``python -m worker.health``: how many worker processes run here, and whether all that should.

Every worker process of the production mode touches ``<tmp>/trackvkf-worker-<pid>.alive``
from its event loop every ``worker_heartbeat_s`` seconds (the loop that also
sends Procrastinate's heartbeat). A worker process counts as alive when its
file is younger than ``worker_stale_after_s`` and the process exists; the file
of a process that is gone is removed.

``trackvkf worker --processes N`` (:mod:`worker.supervisor`) records in
``<tmp>/trackvkf-workers-<pid>.json`` how many children it keeps and which run
now. The check passes (exit 0) when every live supervisor has all its
children alive, or, without a supervisor, when at least one worker process is
alive; it prints ``alive/expected`` either way and fails (exit 1) otherwise:
a child killed and not yet replaced shows as ``1/2``. Used by the container
health check (docker-compose.yml).
"""

from __future__ import annotations

import json
import os
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

from app.runs.settings import WorkerSettings

__all__ = ["alive_file", "status_file", "WorkerCount", "count", "check"]


def alive_file(pid: int) -> Path:
    """Liveness file of worker process ``pid``."""
    return Path(tempfile.gettempdir()) / f"trackvkf-worker-{pid}.alive"


def status_file(pid: int) -> Path:
    """Status file of the supervising process ``pid``: expected and running children."""
    return Path(tempfile.gettempdir()) / f"trackvkf-workers-{pid}.json"


def _pid_of(path: Path, prefix: str, suffix: str) -> int | None:
    text = path.name.removeprefix(prefix).removesuffix(suffix)
    return int(text) if text.isdigit() else None


def _exists(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


@dataclass(frozen=True)
class WorkerCount:
    """Worker processes on this host.

    Attributes
    ----------
    alive : int
        Worker processes alive (fresh liveness file, process exists).
    expected : int
        Worker processes that should run: the supervisors' children, else 1.
    supervised : bool
        Whether a supervisor (``--processes N``) runs here.
    """

    alive: int
    expected: int
    supervised: bool

    @property
    def ok(self) -> bool:
        """All expected worker processes are alive (and at least one)."""
        return self.alive >= max(self.expected, 1)

    def __str__(self) -> str:
        return f"{self.alive}/{self.expected} worker processes alive"


def count(max_age_s: float) -> WorkerCount:
    """Count the worker processes alive here (liveness files younger than ``max_age_s`` s)."""
    if max_age_s <= 0:
        raise ValueError(f"max_age_s must be > 0 s, got {max_age_s}")
    tmp = Path(tempfile.gettempdir())
    now = time.time()
    alive: set[int] = set()
    for path in tmp.glob("trackvkf-worker-*.alive"):
        pid = _pid_of(path, "trackvkf-worker-", ".alive")
        if pid is None:
            continue
        if not _exists(pid):
            path.unlink(missing_ok=True)  # SIGKILL-ed: its file would look alive for a while
            continue
        try:
            if now - path.stat().st_mtime < max_age_s:
                alive.add(pid)
        except FileNotFoundError:
            continue
    expected, supervised_alive, supervised = 0, 0, False
    for path in tmp.glob("trackvkf-workers-*.json"):
        pid = _pid_of(path, "trackvkf-workers-", ".json")
        if pid is None or not _exists(pid):
            continue
        try:
            status = json.loads(path.read_text())
        except (OSError, ValueError):
            continue
        supervised = True
        expected += int(status.get("expected", 0))
        supervised_alive += len(alive & {int(p) for p in status.get("pids", [])})
    if supervised:
        return WorkerCount(alive=supervised_alive, expected=expected, supervised=True)
    return WorkerCount(alive=len(alive), expected=1, supervised=False)


def check(max_age_s: float) -> bool:
    """Whether every worker process that should run here is alive (:func:`count`)."""
    return count(max_age_s).ok


def main() -> int:
    """Print the count; exit status 0 when all expected worker processes are alive.

    Reads the workers' settings group alone (:class:`~app.runs.settings.WorkerSettings`, the same
    ``TRACKVKF_WORKER_*`` variables as the service's settings): the container health check runs this
    every few seconds and need not import the numerics whose constants the other groups name.
    """
    result = count(WorkerSettings().worker_stale_after_s)
    print(result)
    return 0 if result.ok else 1


if __name__ == "__main__":
    sys.exit(main())
