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
    "single_line_csv",
    "upload_peak_growth_mb",
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


def single_line_csv(path: Path, megabytes: int) -> Path:
    """A CSV whose only data line is ``megabytes`` MiB long (a header ``Z11,speed``)."""
    with open(path, "wb") as fh:
        fh.write(b"Z11,speed\n")
        cell = b"1" * (1 << 20)
        for _ in range(megabytes):
            fh.write(cell)
        fh.write(b",20\n")
    return path


def _status_kib(pid: int, key: str) -> int:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith(f"{key}:"):
            return int(line.split()[1])
    raise KeyError(key)


def _chunks(path: Path, size: int = 1 << 20) -> Iterator[bytes]:
    with open(path, "rb") as fh:
        while block := fh.read(size):
            yield block


def upload_peak_growth_mb(
    svc: Any, path: Path, md: dict | None, content_type: str = "text/csv"
) -> tuple[Any, float]:
    """Stream ``path`` as a raw body to a running service (``tests.e2e.conftest.Service``).

    Returns the response and how much the API process's peak RSS grew during
    the upload, MB (``VmHWM`` reset through ``/proc/<pid>/clear_refs`` first).
    """
    pid = svc.api.pid
    Path(f"/proc/{pid}/clear_refs").write_text("5")  # reset VmHWM to the current RSS
    before = _status_kib(pid, "VmRSS")
    with svc.client(timeout=300) as client:
        r = client.post(
            "/api/v1/runs",
            params={"filename": path.name, **({"metadata": json.dumps(md)} if md else {})},
            content=_chunks(path),
            headers={"content-type": content_type},
        )
    return r, (_status_kib(pid, "VmHWM") - before) / 1024
