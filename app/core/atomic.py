"""Write a file atomically: a temporary name beside it, fsync, then ``os.replace``.

Standard library only, so every layer (the run store, the run-file writers)
can use it.
"""

from __future__ import annotations

import contextlib
import os
import uuid
from collections.abc import Iterator
from pathlib import Path

__all__ = ["atomic_path"]


@contextlib.contextmanager
def atomic_path(path: Path, *, suffix: str = ".tmp", must_write: bool = False) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; on success move it onto ``path``.

    Parameters
    ----------
    path : Path
        Final location. Its directory is created if missing.
    suffix : str, optional
        Ending of the temporary name ``.<name>.<random>{suffix}`` (default ``.tmp``).
    must_write : bool, optional
        If true, a ``with`` block that leaves no temporary file raises
        :class:`FileNotFoundError`; by default ``path`` is then left as it is.

    The caller writes the temporary file; when the ``with`` block ends without
    an exception the file is fsynced and renamed onto ``path`` atomically
    (``os.replace``). On an exception the temporary file is removed and
    ``path`` is left untouched.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{uuid.uuid4().hex[:12]}{suffix}")
    try:
        yield tmp
        if must_write or tmp.exists():
            with open(tmp, "rb") as fh:
                os.fsync(fh.fileno())
            os.replace(tmp, path)
    finally:
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()
