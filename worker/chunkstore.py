"""Chunk results of the fan-out mode: in the run store, or in the shared store.

By default chunk results live in the run store directory
(``<run_store>/<run_id>/jobs/<job_id>/chunk-00000.npz``, written atomically by
:func:`worker.pipeline.process_chunk`: temporary file + ``os.replace``). With
a shared store (``TRACKVKF_SHARED_STORE``, an fsspec URL such as
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

from worker.store import RunStore, atomic_path, relative_to_store

__all__ = ["ChunkStore"]

_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]*$")


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

    @property
    def is_local(self) -> bool:
        """Whether results live in the run store directory (no shared store)."""
        return self.shared is None

    def _relative(self, run_id: int, job_id: int, index: int) -> str:
        return relative_to_store(self.run_store, self.run_store.chunk_path(run_id, job_id, index))

    def _relative_named(self, run_id: int, job_id: int, name: str) -> str:
        if not _NAME.match(name):
            raise ValueError(f"name: {name!r} is not a plain file name")
        return relative_to_store(self.run_store, self.run_store.job_dir(run_id, job_id) / name)

    def location(self, run_id: int, job_id: int, index: int) -> str:
        """Where the result of a chunk is (store-relative path or URL; kept in SQL)."""
        rel = self._relative(run_id, job_id, index)
        return rel if self.shared is None else self.shared.location(rel)

    def exists(self, run_id: int, job_id: int, index: int) -> bool:
        """Whether the chunk's result exists (complete: written atomically)."""
        return self._exists(self._relative(run_id, job_id, index))

    def write(self, run_id: int, job_id: int, index: int, produce: Callable[[Path], None]) -> None:
        """Store a chunk result made by ``produce(path)`` (which writes ``path``).

        ``produce`` is :func:`worker.pipeline.process_chunk` with its arguments
        bound; it writes its file atomically. For a shared store the file is
        made in a local temporary directory and uploaded (temporary key, move).
        """
        self._write(self._relative(run_id, job_id, index), produce)

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
            yield [self.shared.get(self._relative(run_id, job_id, i), tmp / f"chunk-{i:05d}.npz")
                   for i in indices]
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
