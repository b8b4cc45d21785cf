"""The shared store of the production mode: run files and chunk results on any fsspec URL.

Hosts do not share a file system in general. With ``TRACKVKF_SHARED_STORE``
set to an fsspec URL (``s3://bucket/trackvkf`` with ``s3fs``,
``gcs://…``, ``file:///mnt/shared/trackvkf``) every host keeps its own run
store directory and the shared store holds, under the run store's layout::

    <url>/<run_id>/run.h5                           published by the API on upload
    <url>/<run_id>/jobs/<job_id>/chunk-00000.npz    written by the worker of the chunk

The API publishes a run's canonical file before the run is committed; a worker
host that lacks the file fetches it once into its own run store (a cache);
chunk results are uploaded there by whichever host computed them and read by
whichever host assembles. Every object is written under a temporary key and
moved onto its final key, so a reader finds it whole or not at all.
"""

from __future__ import annotations

import contextlib
import uuid
from pathlib import Path

import fsspec

from app.core.atomic import atomic_path

__all__ = ["SharedStore"]


class SharedStore:
    """Objects under one fsspec URL, addressed by run-store-relative keys.

    Parameters
    ----------
    url : str
        fsspec URL of the store's root (created on first write).
    """

    def __init__(self, url: str) -> None:
        if not url:
            raise ValueError("url: an fsspec URL is needed, got an empty string")
        self.url = url
        self.fs, root = fsspec.core.url_to_fs(url)
        self.root = root.rstrip("/")

    def key(self, relative: str) -> str:
        """Full key of a store-relative path (``"12/run.h5"``); refuses ``..`` parts."""
        parts = Path(relative).parts
        if not parts or Path(relative).is_absolute() or ".." in parts:
            raise ValueError(f"relative: {relative!r} is not a path inside the store")
        return f"{self.root}/{Path(relative).as_posix()}"

    def location(self, relative: str) -> str:
        """URL of an object (what is kept in SQL and logs)."""
        return self.fs.unstrip_protocol(self.key(relative))

    def exists(self, relative: str) -> bool:
        """Whether the object exists (whole: objects are moved into place)."""
        return bool(self.fs.exists(self.key(relative)))

    def put(self, local: Path, relative: str) -> None:
        """Upload a local file to ``relative``: temporary key, then a move onto the key."""
        final = self.key(relative)
        tmp = f"{final}.{uuid.uuid4().hex[:12]}.tmp"
        self.fs.makedirs(final.rsplit("/", 1)[0], exist_ok=True)
        try:
            self.fs.put_file(str(local), tmp)
            self.fs.mv(tmp, final)
        finally:
            with contextlib.suppress(FileNotFoundError):
                if self.fs.exists(tmp):
                    self.fs.rm(tmp)

    def get(self, relative: str, local: Path) -> Path:
        """Download ``relative`` to ``local`` atomically (temporary file, then rename).

        Raises
        ------
        FileNotFoundError
            If the object does not exist.
        """
        key = self.key(relative)
        if not self.fs.exists(key):
            raise FileNotFoundError(f"{self.location(relative)} is not in the shared store")
        with atomic_path(Path(local)) as tmp:
            self.fs.get_file(key, str(tmp))
        return Path(local)

    def remove_run(self, run_id: int) -> None:
        """Delete every object of run ``run_id`` (no error if there is none)."""
        self.remove_tree(str(int(run_id)))

    def remove_tree(self, relative: str) -> None:
        """Delete every object below ``relative`` (no error if there is none)."""
        key = self.key(relative)
        if self.fs.exists(key):
            self.fs.rm(key, recursive=True)

    def child_names(self, relative: str) -> list[str]:
        """Names of the objects and prefixes directly below ``relative`` (none if it does not exist)."""
        key = self.key(relative)
        try:
            entries = self.fs.ls(key, detail=False)
        except FileNotFoundError:
            return []
        return sorted({str(e).rstrip("/").rsplit("/", 1)[-1] for e in entries})
