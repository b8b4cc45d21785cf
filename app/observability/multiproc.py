"""The multi-process directory of the metrics (no prometheus-client import here: the variable
must be set before prometheus-client is first imported in a process)."""

from __future__ import annotations

import os
import shutil
import tempfile
from pathlib import Path

__all__ = ["MULTIPROC_ENV", "multiprocess_mode", "prepare_multiprocess_dir", "remove_multiprocess_dir"]

MULTIPROC_ENV = "PROMETHEUS_MULTIPROC_DIR"


def multiprocess_mode() -> bool:
    """Whether this process counts into a multi-process directory (``PROMETHEUS_MULTIPROC_DIR``)."""
    return bool(os.environ.get(MULTIPROC_ENV))


def prepare_multiprocess_dir() -> tuple[Path, bool]:
    """Set up the multi-process directory before the API processes start (``trackvkf serve``).

    When ``PROMETHEUS_MULTIPROC_DIR`` is set, its old files are removed
    (counters restart with the service, as Prometheus expects); otherwise a
    fresh temporary directory is made and the variable set for the processes
    that ``serve`` starts.

    Returns
    -------
    (Path, bool)
        The directory, and whether it was made here (remove it at the end:
        :func:`remove_multiprocess_dir`).
    """
    given = os.environ.get(MULTIPROC_ENV)
    if given:
        path = Path(given)
        path.mkdir(parents=True, exist_ok=True)
        for entry in path.glob("*.db"):
            entry.unlink(missing_ok=True)
        return path, False
    path = Path(tempfile.mkdtemp(prefix="trackvkf-metrics-"))
    os.environ[MULTIPROC_ENV] = str(path)
    return path, True


def remove_multiprocess_dir(path: Path) -> None:
    """Remove a directory made by :func:`prepare_multiprocess_dir`, and the variable set for it (a
    process that goes on after ``serve``, such as a test runner, must not count into a directory
    that is gone)."""
    shutil.rmtree(path, ignore_errors=True)
    if os.environ.get(MULTIPROC_ENV) == str(path):
        del os.environ[MULTIPROC_ENV]
