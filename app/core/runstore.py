"""Layout of the run store: where run files, uploads and chunk results live.

The run store is a directory (``Settings.run_store``)::

    <root>/.uploads/<token>/          an upload in progress (removed on any error),
                                      flock-ed by the API process receiving it
    <root>/<run_id>/run.h5            the canonical HDF5 file of a run
    <root>/<run_id>/jobs/<job_id>/chunk-00000.npz   chunk results of a job (kept while the
                                                    job is queued or running only)

In the production mode on hosts without a common file system the same layout
is mirrored in a shared fsspec store (:mod:`app.core.sharedstore`).

Every path is generated here from integer ids and random tokens: a client's
file name never becomes a path. Files are written through :func:`app.core.atomic.atomic_path`
(temporary name in the same directory, fsync, ``os.replace``), so a reader
sees either the whole file or none.

An upload directory is owned by the process receiving it: that process holds
an exclusive ``flock`` on the directory for as long as the upload lasts, and
the kernel drops it when the process ends, however it ends (SIGKILL, power
loss). :meth:`RunStore.sweep_uploads` (run when an API process starts)
removes every upload directory it can lock, i.e. every one no live process
owns, and leaves the uploads in progress of the other API processes alone.
"""

from __future__ import annotations

import contextlib
import fcntl
import logging
import operator
import os
import shutil
import time
import uuid
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from app.core.sharedstore import SharedStore

__all__ = ["RunStore", "RUN_FILE_NAME", "chunk_file_name"]

log = logging.getLogger(__name__)

RUN_FILE_NAME = "run.h5"
_UPLOADS = ".uploads"


def chunk_file_name(index: int) -> str:
    """File name of chunk ``index`` of a job (the run store's and a local work directory's):
    ``chunk-00000.npz`` …"""
    return f"chunk-{index:05d}.npz"


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
        self._upload_locks: dict[Path, int] = {}
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
        return self.job_dir(run_id, job_id) / chunk_file_name(index)

    # --- uploads ------------------------------------------------------------
    def new_upload_dir(self) -> Path:
        """Create and return a fresh, empty directory for one upload, owned by this process.

        The directory is locked (``flock``) until :meth:`release_upload_dir`;
        :meth:`sweep_uploads` of any process leaves it alone meanwhile.
        """
        self.uploads_dir.mkdir(parents=True, exist_ok=True)
        while True:
            path = self.uploads_dir / uuid.uuid4().hex
            path.mkdir()
            fd = os.open(path, os.O_RDONLY | os.O_DIRECTORY)
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:  # a sweep took it between mkdir and flock and removes it
                os.close(fd)
                continue
            except OSError as exc:  # no flock here (some network file systems): the age rule applies
                log.debug("no flock on %s (%s): uploads are swept by age only", path, exc)
            try:
                still_there = os.stat(path).st_ino == os.fstat(fd).st_ino
            except FileNotFoundError:
                still_there = False
            if still_there:
                self._upload_locks[path] = fd
                return path
            os.close(fd)

    def release_upload_dir(self, path: Path) -> None:
        """Remove an upload directory (if still there) and drop this process's lock on it."""
        shutil.rmtree(path, ignore_errors=True)
        fd = self._upload_locks.pop(Path(path), None)
        if fd is not None:
            os.close(fd)

    @contextlib.contextmanager
    def upload_dir(self) -> Iterator[Path]:
        """A fresh upload directory owned by this process for the ``with`` block, removed after it.

        Move it away inside the block to keep its contents (:meth:`install_run_dir`).
        """
        path = self.new_upload_dir()
        try:
            yield path
        finally:
            self.release_upload_dir(path)

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

    def job_ids_with_files(self, run_id: int) -> list[int]:
        """Ids of the jobs of run ``run_id`` that have a directory here or in the shared store."""
        jobs = self.run_dir(run_id) / "jobs"
        ids = {int(p.name) for p in jobs.iterdir() if p.is_dir() and p.name.isdigit()} if jobs.is_dir() else set()
        if self.shared is not None:
            ids |= {int(n) for n in self.shared.child_names(f"{int(run_id)}/jobs") if n.isdigit()}
        return sorted(ids)

    def remove_job_files(self, run_id: int, job_id: int) -> None:
        """Delete the chunk and wheel files of job ``job_id``, in the shared store too (no error if absent)."""
        shutil.rmtree(self.job_dir(run_id, job_id), ignore_errors=True)
        if self.shared is not None:
            self.shared.remove_tree(f"{_check_id(run_id, 'run_id')}/jobs/{_check_id(job_id, 'job_id')}")

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
        """Remove the uploads no live process owns (left by a crashed or killed API).

        An upload directory is removed when its ``flock`` can be taken (its
        owner is gone); on a file system without ``flock`` (some network file
        systems) when it is older than ``older_than_s`` seconds. Stray files in
        the uploads directory are removed by age.

        Returns
        -------
        int
            Number of upload directories (and stray files) removed.
        """
        if not self.uploads_dir.is_dir():
            return 0
        cutoff = time.time() - older_than_s
        removed = 0
        for entry in self.uploads_dir.iterdir():
            try:
                if entry.is_dir() and not entry.is_symlink():
                    removed += self._sweep_upload_dir(entry, cutoff)
                elif entry.lstat().st_mtime < cutoff:
                    entry.unlink()
                    removed += 1
            except FileNotFoundError:
                continue
        return removed

    def _sweep_upload_dir(self, path: Path, cutoff: float) -> int:
        fd = os.open(path, os.O_RDONLY | os.O_DIRECTORY)
        try:
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                return 0  # a live process is receiving it
            except OSError:
                if path.stat().st_mtime >= cutoff:
                    return 0
            shutil.rmtree(path, ignore_errors=True)  # under the lock: its creator retries
            return 1
        finally:
            os.close(fd)

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
