"""``python -m worker.health``: liveness of the Procrastinate worker processes here.

Every worker process of the production mode touches ``<tmp>/trackvkf-worker-<pid>.alive``
from its event loop every ``worker_heartbeat_s`` seconds (the loop that also
sends Procrastinate's heartbeat). The check passes (exit 0) when at least one
such file is younger than ``worker_stale_after_s``; a hung or dead worker
fails it (exit 1). Used by the container health check (docker-compose.yml).
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

from app.core.config import get_settings

__all__ = ["alive_file", "check"]


def alive_file(pid: int) -> Path:
    """Liveness file of worker process ``pid``."""
    return Path(tempfile.gettempdir()) / f"trackvkf-worker-{pid}.alive"


def check(max_age_s: float) -> bool:
    """Whether some worker process on this host touched its file within ``max_age_s`` s."""
    if max_age_s <= 0:
        raise ValueError(f"max_age_s must be > 0 s, got {max_age_s}")
    now = time.time()
    for path in Path(tempfile.gettempdir()).glob("trackvkf-worker-*.alive"):
        try:
            if now - path.stat().st_mtime < max_age_s:
                return True
        except FileNotFoundError:
            continue
    return False


if __name__ == "__main__":
    sys.exit(0 if check(get_settings().worker_stale_after_s) else 1)
