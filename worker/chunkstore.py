"""Chunk results of the fan-out mode on any fsspec file system.

By default chunk results live in the run store directory
(``<run_store>/<run_id>/jobs/<job_id>/chunk-00000.npz``, written atomically by
:func:`worker.pipeline.process_chunk`: temporary file + ``os.replace``). With
``TRACKVKF_CHUNK_STORE`` set to an fsspec URL (``file:///shared/chunks``,
``s3://bucket/trackvkf-chunks`` with ``s3fs``, ``memory://`` in tests) they go
there instead, under the same relative layout: the chunk is computed into a
local temporary file, uploaded under a temporary name and renamed onto its
final key (on object stores the final object appears whole with one request).
Either way a result either exists whole or not at all, so its presence is
the proof that the chunk is done.
"""

from __future__ import annotations

import contextlib
import shutil
import tempfile
import uuid
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path

import fsspec

from worker.store import RunStore, relative_to_store

__all__ = ["ChunkStore"]


class ChunkStore:
    """Chunk result files of jobs, in the run store or at an fsspec URL.

    Parameters
    ----------
    run_store : RunStore
        The run store (the default location).
    url : str, optional
        fsspec URL of a separate chunk store shared by the worker hosts.
    """

    def __init__(self, run_store: RunStore, url: str | None = None) -> None:
        self.run_store = run_store
        self.url = url or None
        if self.url is None:
            self.fs = None
            self.root = ""
        else:
            self.fs, self.root = fsspec.core.url_to_fs(self.url)
            self.root = self.root.rstrip("/")

    @property
    def is_local(self) -> bool:
        """Whether results live in the run store directory (the default)."""
        return self.fs is None

    def _key(self, run_id: int, job_id: int, index: int) -> str:
        rel = relative_to_store(self.run_store, self.run_store.chunk_path(run_id, job_id, index))
        return f"{self.root}/{rel}"

    def location(self, run_id: int, job_id: int, index: int) -> str:
        """Where the result of a chunk is (store-relative path or fsspec URL; kept in SQL)."""
        if self.is_local:
            return relative_to_store(self.run_store, self.run_store.chunk_path(run_id, job_id, index))
        return self.fs.unstrip_protocol(self._key(run_id, job_id, index))

    def exists(self, run_id: int, job_id: int, index: int) -> bool:
        """Whether the chunk's result exists (complete: written atomically)."""
        if self.is_local:
            return self.run_store.chunk_path(run_id, job_id, index).is_file()
        return bool(self.fs.exists(self._key(run_id, job_id, index)))

    def write(self, run_id: int, job_id: int, index: int, produce: Callable[[Path], None]) -> None:
        """Store a chunk result made by ``produce(path)`` (which writes ``path``).

        ``produce`` is :func:`worker.pipeline.process_chunk` with its arguments
        bound; it writes its file atomically. For a remote store the file is
        made in a local temporary directory, uploaded under a temporary key and
        moved onto the final key.
        """
        if self.is_local:
            produce(self.run_store.chunk_path(run_id, job_id, index))
            return
        final = self._key(run_id, job_id, index)
        tmp_key = f"{final}.{uuid.uuid4().hex[:12]}.tmp"
        with tempfile.TemporaryDirectory(prefix="trackvkf-chunk-") as tmp:
            local = Path(tmp) / Path(final).name
            produce(local)
            self.fs.makedirs(final.rsplit("/", 1)[0], exist_ok=True)
            try:
                self.fs.put_file(str(local), tmp_key)
                self.fs.mv(tmp_key, final)
            finally:
                with contextlib.suppress(FileNotFoundError):
                    if self.fs.exists(tmp_key):
                        self.fs.rm(tmp_key)

    @contextlib.contextmanager
    def local_copies(self, run_id: int, job_id: int, indices: Sequence[int]) -> Iterator[list[Path]]:
        """Local paths of chunk results (downloaded to a temporary directory if remote)."""
        if self.is_local:
            yield [self.run_store.chunk_path(run_id, job_id, i) for i in indices]
            return
        tmp = Path(tempfile.mkdtemp(prefix="trackvkf-assemble-"))
        try:
            paths = []
            for i in indices:
                local = tmp / f"chunk-{i:05d}.npz"
                self.fs.get_file(self._key(run_id, job_id, i), str(local))
                paths.append(local)
            yield paths
        finally:
            shutil.rmtree(tmp, ignore_errors=True)

    def remove_run(self, run_id: int) -> None:
        """Delete the chunk results of a run (no error if absent)."""
        if self.is_local:
            return  # inside the run directory: removed with the run
        key = f"{self.root}/{int(run_id)}"
        if self.fs.exists(key):
            self.fs.rm(key, recursive=True)
