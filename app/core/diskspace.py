"""Free space of the file systems the service writes to: checked before and while writing.

A full disk must never take a process down or leave a half-written file: the
writers check the free space of the target against what they are about to
write plus a reserve (``TRACKVKF_MIN_FREE_BYTES``) and stop with
:class:`DiskFullError` first; an ``ENOSPC`` that still happens (another
process filled the disk meanwhile) is recognised by :func:`is_disk_full` and
answered the same way (HTTP 507, a failed job).

Standard library only, so every layer can use it.
"""

from __future__ import annotations

import errno
import os
import sqlite3
from pathlib import Path

from app.core.i18n import _

__all__ = ["DiskFullError", "free_bytes", "require_free", "is_disk_full", "describe_bytes"]

#: errno values meaning "no room": the file system is full or the user's quota is used up
_FULL_ERRNOS = frozenset({errno.ENOSPC, errno.EDQUOT})


def describe_bytes(n: int) -> str:
    """``n`` bytes for people: ``"11.6 MB"`` (decimal units)."""
    value = float(n)
    for unit in ("B", "kB", "MB", "GB", "TB"):
        if abs(value) < 1000 or unit == "TB":
            return f"{value:.0f} {unit}" if unit == "B" else f"{value:.1f} {unit}"
        value /= 1000
    raise AssertionError("unreachable")


class DiskFullError(OSError):
    """Not enough free space to write (``errno.ENOSPC``), found before or while writing.

    Parameters
    ----------
    path : Path
        Where the data were to be written.
    message : str
        What did not fit.
    """

    def __init__(self, path: Path | str, message: str) -> None:
        super().__init__(errno.ENOSPC, message, str(path))
        self.message = message

    def __str__(self) -> str:
        return self.message


def free_bytes(path: Path | str) -> int:
    """Bytes available to this process on the file system holding ``path`` (which must exist)."""
    st = os.statvfs(path)
    return int(st.f_bavail) * int(st.f_frsize)


def require_free(path: Path | str, needed: int, reserve: int, what: str = "the data") -> int:
    """Check that writing ``needed`` bytes at ``path`` leaves at least ``reserve`` bytes free.

    Parameters
    ----------
    path : Path
        An existing file or directory on the file system written to.
    needed : int
        Bytes about to be written.
    reserve : int
        Bytes that must stay free afterwards (``TRACKVKF_MIN_FREE_BYTES``).
    what : str
        What is written, for the message.

    Returns
    -------
    int
        The free bytes found.

    Raises
    ------
    DiskFullError
        If ``needed + reserve`` exceeds the free space.
    """
    if needed < 0 or reserve < 0:
        raise ValueError(f"needed and reserve must be >= 0, got {needed}, {reserve}")
    free = free_bytes(path)
    if needed + reserve > free:
        raise DiskFullError(
            path,
            _("not enough free space for {what}: {needed} needed, {free} free, {reserve} kept in reserve "
              "(TRACKVKF_MIN_FREE_BYTES)", what=what, needed=describe_bytes(needed), free=describe_bytes(free),
              reserve=describe_bytes(reserve)),
        )
    return free


def is_disk_full(exc: BaseException) -> bool:
    """Whether ``exc`` (or what caused it) says the disk is full.

    Recognises :class:`OSError` with ``ENOSPC``/``EDQUOT`` (also from libhdf5,
    which h5py raises with the errno) and SQLite's "database or disk is full",
    also wrapped by SQLAlchemy (``exc.orig``) or chained (``__cause__``).
    """
    seen: set[int] = set()
    todo: list[BaseException | None] = [exc]
    while todo:
        current = todo.pop()
        if current is None or id(current) in seen:
            continue
        seen.add(id(current))
        if isinstance(current, OSError) and current.errno in _FULL_ERRNOS:
            return True
        if isinstance(current, sqlite3.OperationalError) and "disk is full" in str(current):
            return True
        todo.extend([getattr(current, "orig", None), current.__cause__, current.__context__])
    return False
