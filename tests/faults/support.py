"""Helpers of the fault tests: distinct small run files, uploads, the audit trail."""

from __future__ import annotations

import json
import shutil
import subprocess
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from tests.api import runfiles

__all__ = [
    "csv_run",
    "hdf5_run",
    "upload_file",
    "upload_csv",
    "last_upload_audit",
    "mounted_tmpfs",
    "TmpfsUnavailable",
]

_counter = iter(range(1, 1_000_000))


def csv_run(directory: Path, n: int = runfiles.N) -> Path:
    """A valid CSV run file whose content (and sha256) differs from every earlier one."""
    seed = next(_counter)
    return runfiles.write_csv(Path(directory) / f"run-{seed}.csv", runfiles.channels(n=n, seed=seed))


def hdf5_run(directory: Path, md: dict[str, Any] | None = None, n: int = runfiles.N) -> Path:
    """A valid HDF5 run file (metadata attribute ``md``) differing from every earlier one."""
    seed = next(_counter)
    return runfiles.write_hdf5(Path(directory) / f"run-{seed}.h5", runfiles.channels(n=n, seed=seed), md)


def upload_file(client: Any, path: Path, metadata_text: str | None = None, ctype: str = "application/octet-stream"):
    """POST a run file as multipart form (with the metadata text, if given)."""
    data = {} if metadata_text is None else {"metadata": metadata_text}
    return client.post(
        "/api/v1/runs", files={"file": (path.name, path.read_bytes(), ctype)}, data=data
    )


def upload_csv(client: Any, directory: Path, metadata_text: str | None = None, **changes: Any):
    """Upload a fresh CSV run with ``metadata_text`` (default: valid metadata with ``changes``)."""
    if metadata_text is None:
        metadata_text = json.dumps(runfiles.metadata(**changes))
    return upload_file(client, csv_run(directory), metadata_text, "text/csv")


def last_upload_audit(client: Any) -> dict[str, Any]:
    """The newest ``run.upload`` audit entry (the client must be an admin)."""
    items = client.get("/api/v1/audit", params={"action": "run.upload", "limit": 1}).json()["items"]
    assert items, "no run.upload audit entry"
    return items[0]


class TmpfsUnavailable(RuntimeError):
    """Mounting a tmpfs is not permitted here (not root, or no mount in the container)."""


@contextmanager
def mounted_tmpfs(directory: Path, size_bytes: int) -> Iterator[Path]:
    """Mount a tmpfs of ``size_bytes`` on ``directory`` (created) for the ``with`` block.

    Raises
    ------
    TmpfsUnavailable
        If ``mount`` is missing or refused (tests skip with the reason).
    """
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    if shutil.which("mount") is None:
        raise TmpfsUnavailable("no mount command")
    done = subprocess.run(
        ["mount", "-t", "tmpfs", "-o", f"size={int(size_bytes)}", "tmpfs", str(directory)],
        capture_output=True, text=True, check=False,
    )
    if done.returncode != 0:
        raise TmpfsUnavailable(f"mount -t tmpfs refused: {done.stderr.strip() or done.returncode}")
    try:
        yield directory
    finally:
        subprocess.run(["umount", "-l", str(directory)], capture_output=True, check=False)
