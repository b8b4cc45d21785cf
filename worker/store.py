"""Run-store helpers of the worker: chunk result paths, done checks, clean-up.

The layout itself lives in :mod:`app.core.runstore` (the API needs it too);
this module adds what only the worker does with it. A chunk's result file is
the proof that the chunk is done: it is written atomically (temporary file +
``os.replace``), so it either exists whole or not at all.
"""

from __future__ import annotations

import contextlib
import re
from pathlib import Path

from app.core.runstore import RUN_FILE_NAME, RunStore, atomic_path

__all__ = [
    "RunStore",
    "atomic_path",
    "RUN_FILE_NAME",
    "chunk_done",
    "relative_to_store",
    "discard_partial_files",
]

#: finished files of a job: chunk results and assembled wheel results
_JOB_FILE_NAME = re.compile(r"^(chunk-\d{5}\.npz|wheel-\w+\.json)$")


def chunk_done(path: Path) -> bool:
    """Whether the chunk result at ``path`` exists (written atomically, so complete)."""
    return Path(path).is_file()


def relative_to_store(store: RunStore, path: Path) -> str:
    """``path`` relative to the store root, with forward slashes (stored in SQL)."""
    return Path(path).resolve().relative_to(store.root).as_posix()


def discard_partial_files(job_dir: Path) -> int:
    """Remove files in a job directory that are not finished chunk or wheel results.

    Temporary files of a writer killed mid-write (SIGKILL) are left behind by
    design; they are removed when the job is (re)started.

    Returns
    -------
    int
        Number of files removed.
    """
    job_dir = Path(job_dir)
    if not job_dir.is_dir():
        return 0
    removed = 0
    for entry in job_dir.iterdir():
        if entry.is_file() and not _JOB_FILE_NAME.match(entry.name):
            with contextlib.suppress(FileNotFoundError):
                entry.unlink()
                removed += 1
    return removed
