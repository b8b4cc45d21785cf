"""Where the chunk results of jobs live: in the run store, or in its shared store.

Both worker modes (the local job loop and the Procrastinate tasks) keep a
job's chunk files (:mod:`app.pipeline.chunkfile`) through one
:class:`ChunkStore`. By default they live in the run store directory
(``<run_store>/<run_id>/jobs/<job_id>/chunk-00000.npz``, written atomically by
:func:`app.pipeline.process_chunk`: temporary file + ``os.replace``). With a
shared store (``TRACKVKF_SHARED_STORE``, an fsspec URL such as
``s3://bucket/trackvkf`` with ``s3fs``; see :mod:`app.core.sharedstore`) they
go there instead, under the same relative layout: the chunk is computed into a
local temporary file, uploaded under a temporary key and moved onto its final
key. Either way a result either exists whole or not at all, so its presence
is the proof that the chunk is done.
"""

from __future__ import annotations

import contextlib
import re
import shutil
import tempfile
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any

from app.core.atomic import atomic_path
from app.core.runstore import RunStore

__all__ = ["ChunkStore"]

_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]*$")
#: finished files of a job: chunk results and assembled wheel results
_JOB_FILE_NAME = re.compile(r"^(chunk-\d{5}\.npz|wheel-\w+\.json)$")


class ChunkStore:
    """Chunk result files (and other files) of jobs, in the run store or in its shared store.

    Parameters
    ----------
    run_store : RunStore
        The run store; its ``shared`` store, when set, holds the results.
    """

    def __init__(self, run_store: RunStore) -> None:
        self.run_store = run_store
        self.shared = run_store.shared

    def __reduce__(self) -> tuple[Any, ...]:
        # pickled as its run store's root and shared URL (chunk-pool processes)
        url = self.shared.url if self.shared is not None else None
        return (_chunk_store, (str(self.run_store.root), url))

    @property
    def is_local(self) -> bool:
        """Whether results live in the run store directory (no shared store)."""
        return self.shared is None

    def _relative(self, run_id: int, job_id: int, index: int) -> str:
        return self._store_relative(self.run_store.chunk_path(run_id, job_id, index))

    def _relative_named(self, run_id: int, job_id: int, name: str) -> str:
        if not _NAME.match(name):
            raise ValueError(f"name: {name!r} is not a plain file name")
        return self._store_relative(self.run_store.job_dir(run_id, job_id) / name)

    def _store_relative(self, path: Path) -> str:
        """``path`` relative to the store root, with forward slashes (stored in SQL)."""
        return Path(path).resolve().relative_to(self.run_store.root).as_posix()

    def location(self, run_id: int, job_id: int, index: int) -> str:
        """Where the result of a chunk is (store-relative path or URL; kept in SQL)."""
        rel = self._relative(run_id, job_id, index)
        return rel if self.shared is None else self.shared.location(rel)

    def exists(self, run_id: int, job_id: int, index: int) -> bool:
        """Whether the chunk's result exists (complete: written atomically)."""
        return self._exists(self._relative(run_id, job_id, index))

    def write(self, run_id: int, job_id: int, index: int, produce: Callable[[Path], None]) -> None:
        """Store a chunk result made by ``produce(path)`` (which writes ``path``).

        ``produce`` is :func:`app.pipeline.process_chunk` with its arguments
        bound; it writes its file atomically. For a shared store the file is
        made in a local temporary directory and uploaded (temporary key, move).
        """
        self._write(self._relative(run_id, job_id, index), produce)

    def discard_partial(self, run_id: int, job_id: int) -> int:
        """Remove files in a job's directory that are not finished chunk or wheel results.

        Temporary files of a writer killed mid-write (SIGKILL) are left behind
        by design; they are removed when the job is (re)started. Nothing to do
        with a shared store (objects are moved onto their keys whole).

        Returns
        -------
        int
            Number of files removed.
        """
        job_dir = self.run_store.job_dir(run_id, job_id)
        if self.shared is not None or not job_dir.is_dir():
            return 0
        removed = 0
        for entry in job_dir.iterdir():
            if entry.is_file() and not _JOB_FILE_NAME.match(entry.name):
                with contextlib.suppress(FileNotFoundError):
                    entry.unlink()
                    removed += 1
        return removed

    # --- other files of a job (the assembled wheel results) --------------------
    def exists_named(self, run_id: int, job_id: int, name: str) -> bool:
        """Whether the job's file ``name`` exists (complete: written atomically)."""
        return self._exists(self._relative_named(run_id, job_id, name))

    def write_bytes(self, run_id: int, job_id: int, name: str, data: bytes) -> None:
        """Store ``data`` as the job's file ``name``, atomically."""

        def produce(path: Path) -> None:
            with atomic_path(path) as tmp:
                tmp.write_bytes(data)

        self._write(self._relative_named(run_id, job_id, name), produce)

    def read_bytes(self, run_id: int, job_id: int, name: str) -> bytes:
        """Contents of the job's file ``name`` (FileNotFoundError if absent)."""
        rel = self._relative_named(run_id, job_id, name)
        if self.shared is None:
            return self.run_store.resolve(rel).read_bytes()
        with tempfile.TemporaryDirectory(prefix="trackvkf-read-") as tmp:
            return self.shared.get(rel, Path(tmp) / name).read_bytes()

    @contextlib.contextmanager
    def local_copies(self, run_id: int, job_id: int, indices: Sequence[int]) -> Iterator[list[Path]]:
        """Local paths of chunk results (downloaded to a temporary directory if shared)."""
        if self.shared is None:
            yield [self.run_store.chunk_path(run_id, job_id, i) for i in indices]
            return
        tmp = Path(tempfile.mkdtemp(prefix="trackvkf-assemble-"))
        try:
            rels = [self._relative(run_id, job_id, i) for i in indices]
            yield [self.shared.get(rel, tmp / Path(rel).name) for rel in rels]
        finally:
            shutil.rmtree(tmp, ignore_errors=True)

    # --- helpers ---------------------------------------------------------------
    def _exists(self, rel: str) -> bool:
        if self.shared is None:
            return self.run_store.resolve(rel).is_file()
        return self.shared.exists(rel)

    def _write(self, rel: str, produce: Callable[[Path], None]) -> None:
        if self.shared is None:
            produce(self.run_store.resolve(rel))
            return
        with tempfile.TemporaryDirectory(prefix="trackvkf-chunk-") as tmp:
            local = Path(tmp) / Path(rel).name
            produce(local)
            self.shared.put(local, rel)


def _chunk_store(root: str, shared_url: str | None) -> ChunkStore:
    return ChunkStore(RunStore(root, shared_url))
