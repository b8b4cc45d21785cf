"""Layout of the run store: where run files, uploads and chunk results live.

The run store is a directory (``Settings.run_store``)::

    <root>/.uploads/<token>/          an upload in progress (removed on any error)
    <root>/<run_id>/run.h5            the canonical HDF5 file of a run
    <root>/<run_id>/jobs/<job_id>/chunk-00000.npz   chunk results of a job

In the production mode on hosts without a common file system the same layout
is mirrored in a shared fsspec store (:mod:`app.core.sharedstore`).

Every path is generated here from integer ids and random tokens: a client's
file name never becomes a path. Files are written through :func:`atomic_path`
(temporary name in the same directory, fsync, ``os.replace``), so a reader
sees either the whole file or none.
"""

from __future__ import annotations

import logging
import operator
import os
import shutil
import time
import uuid
from pathlib import Path
from typing import TYPE_CHECKING

from app.core.atomic import atomic_path

if TYPE_CHECKING:
    from app.core.sharedstore import SharedStore

__all__ = ["RunStore", "atomic_path", "RUN_FILE_NAME"]

log = logging.getLogger(__name__)

RUN_FILE_NAME = "run.h5"
_UPLOADS = ".uploads"


class RunStore:
    """Paths and file operations of the run store rooted at ``root``.

    Parameters
    ----------
    root : Path
        Directory of the run store; created on first use.
    shared_url : str, optional
        fsspec URL of the production mode's shared store
        (:class:`app.core.sharedstore.SharedStore`): run files are published
        there on upload and fetched from there by hosts that lack them; a
        run's objects there are removed with the run.
    """

    def __init__(self, root: Path | str, shared_url: str | None = None) -> None:
        self.root = Path(root).resolve()
        self.shared: SharedStore | None = None
        if shared_url:
            from app.core.sharedstore import SharedStore

            self.shared = SharedStore(shared_url)

    # --- layout -----------------------------------------------------------
    @property
    def uploads_dir(self) -> Path:
        """Directory holding uploads in progress."""
        return self.root / _UPLOADS

    def run_dir(self, run_id: int) -> Path:
        """Directory of run ``run_id``."""
        return self.root / str(_check_id(run_id, "run_id"))

    def run_file(self, run_id: int) -> Path:
        """Canonical HDF5 file of run ``run_id``."""
        return self.run_dir(run_id) / RUN_FILE_NAME

    def relative_run_file(self, run_id: int) -> str:
        """Path of the run file relative to the store root (stored in SQL)."""
        return f"{_check_id(run_id, 'run_id')}/{RUN_FILE_NAME}"

    def revised_run_file(self, relative: str) -> str:
        """Store-relative path of the next revision of a run file (its metadata corrected):
        ``7/run.h5`` → ``7/run-r2.h5`` → ``7/run-r3.h5``. A new name, so no host keeps
        using a cached copy of the previous revision."""
        head, _, name = relative.rpartition("/")
        stem = name.removesuffix(".h5")
        revision = int(stem.rpartition("-r")[2]) if stem.startswith("run-r") else 1
        return f"{head}/run-r{revision + 1}.h5"

    def resolve(self, relative: str) -> Path:
        """Absolute path of a store-relative path; refuses paths leaving the store."""
        path = (self.root / relative).resolve()
        if self.root not in path.parents:
            raise ValueError(f"relative: path {relative!r} leaves the run store")
        return path

    def job_dir(self, run_id: int, job_id: int) -> Path:
        """Working directory of job ``job_id`` of run ``run_id`` (chunk results)."""
        return self.run_dir(run_id) / "jobs" / str(_check_id(job_id, "job_id"))

    def chunk_path(self, run_id: int, job_id: int, index: int) -> Path:
        """Result file of chunk ``index`` of a job: ``chunk-XXXXX.npz``."""
        if index < 0:
            raise ValueError(f"index must be >= 0, got {index}")
        return self.job_dir(run_id, job_id) / f"chunk-{index:05d}.npz"

    # --- uploads ------------------------------------------------------------
    def new_upload_dir(self) -> Path:
        """Create and return a fresh, empty directory for one upload."""
        path = self.uploads_dir / uuid.uuid4().hex
        path.mkdir(parents=True)
        return path

    def install_run_dir(self, upload_dir: Path, run_id: int) -> Path:
        """Move a finished upload directory to ``run_dir(run_id)`` atomically.

        A directory already at the target belongs to no run (left by a crash
        between this move and the database commit) and is removed first.
        """
        target = self.run_dir(run_id)
        if target.exists():
            log.warning("removing orphan run directory %s", target)
            shutil.rmtree(target, ignore_errors=True)
        os.replace(upload_dir, target)
        return target

    def remove_run(self, run_id: int) -> None:
        """Delete everything stored for run ``run_id``, in the shared store too (no error if absent)."""
        shutil.rmtree(self.run_dir(run_id), ignore_errors=True)
        if self.shared is not None:
            self.shared.remove_run(run_id)

    # --- shared store (production mode on hosts without a common file system) ---
    def publish_run_file(self, run_id: int) -> None:
        """Upload the run's canonical file to the shared store (nothing without one)."""
        if self.shared is not None:
            self.shared.put(self.run_file(run_id), self.relative_run_file(run_id))

    def publish_file(self, relative: str) -> None:
        """Upload a store-relative file to the shared store (nothing without one)."""
        if self.shared is not None:
            self.shared.put(self.resolve(relative), relative)

    def local_file(self, relative: str) -> Path:
        """Local path of a store-relative file, fetched from the shared store if missing here.

        Raises
        ------
        FileNotFoundError
            If the file is neither here nor in the shared store.
        """
        path = self.resolve(relative)
        if path.is_file():
            return path
        if self.shared is None:
            raise FileNotFoundError(f"{relative} is missing from the run store {self.root}")
        log.info("fetching %s from the shared store", self.shared.location(relative))
        return self.shared.get(relative, path)

    def remove_tree(self, path: Path) -> None:
        """Delete a directory inside the store (no error if absent)."""
        path = Path(path).resolve()
        if self.root not in path.parents:
            raise ValueError(f"path: {path} is not inside the run store")
        shutil.rmtree(path, ignore_errors=True)

    def sweep_uploads(self, older_than_s: float) -> int:
        """Remove uploads in progress older than ``older_than_s`` seconds.

        Returns
        -------
        int
            Number of upload directories removed.
        """
        if not self.uploads_dir.is_dir():
            return 0
        cutoff = time.time() - older_than_s
        removed = 0
        for entry in self.uploads_dir.iterdir():
            try:
                if entry.stat().st_mtime < cutoff:
                    shutil.rmtree(entry, ignore_errors=True) if entry.is_dir() else entry.unlink()
                    removed += 1
            except FileNotFoundError:
                continue
        return removed

    def run_ids_on_disk(self) -> list[int]:
        """Ids of the run directories present in the store."""
        if not self.root.is_dir():
            return []
        return sorted(int(p.name) for p in self.root.iterdir() if p.is_dir() and p.name.isdigit())


def _check_id(value: int, name: str) -> int:
    try:
        number = operator.index(value)
    except TypeError:
        number = 0
    if isinstance(value, bool) or number < 1:
        raise ValueError(f"{name} must be a positive integer, got {value!r}")
    return number
