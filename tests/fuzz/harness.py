"""Run a fuzz corpus through a parser in a child process, with a time limit per file.

The child (forked from the test process) parses the files one after another
and reports each outcome; the parent waits at most ``per_file_s`` for each.
A file that takes longer (a hang) or kills the child (a crash in C code) is
recorded as such, the child is replaced, and the run goes on with the next
file, so one bad file fails the test without hanging CI or hiding the others.
"""

from __future__ import annotations

import hashlib
import multiprocessing
import time
import traceback
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

__all__ = ["Outcome", "run_corpus", "ingest_digest"]


@dataclass(frozen=True)
class Outcome:
    """What parsing one file gave.

    ``kind``: ``"refused"`` (a :class:`RunFileError`: ``detail`` is its field and
    message), ``"accepted"`` (``detail`` is the digest of what was read),
    ``"error"`` (any other exception: ``detail`` is its traceback), ``"hang"``
    or ``"crash"``.
    """

    kind: str
    detail: str
    seconds: float


def _child(conn, parse: Callable[[Path], str], files: Sequence[Path], start: int) -> None:  # noqa: ANN001
    import faulthandler

    from app.io.errors import RunFileError

    faulthandler.disable()  # a crash is an outcome here, not a report for the test log
    for i in range(start, len(files)):
        conn.send(("start", i))
        t0 = time.perf_counter()
        try:
            outcome = ("accepted", parse(files[i]))
        except RunFileError as exc:
            outcome = ("refused", f"{exc.field}: {exc.message}")
        except BaseException:  # noqa: BLE001 - reported to the test
            outcome = ("error", traceback.format_exc()[-3000:])
        conn.send(("done", i, *outcome, time.perf_counter() - t0))
    conn.close()


def run_corpus(parse: Callable[[Path], str], files: Sequence[Path], per_file_s: float) -> list[Outcome]:
    """Parse every file with ``parse`` (returns a digest or raises) in a child process.

    Parameters
    ----------
    parse : callable
        Module-level function ``parse(path) -> str``.
    files : sequence of Path
        The corpus.
    per_file_s : float
        Time limit per file, s.
    """
    ctx = multiprocessing.get_context("fork")
    out: list[Outcome | None] = [None] * len(files)
    start = 0
    while start < len(files):
        receive, send = ctx.Pipe(duplex=False)
        proc = ctx.Process(target=_child, args=(send, parse, files, start))  # may start children
        proc.start()
        send.close()
        current, t0 = None, time.perf_counter()
        try:
            while True:
                if not receive.poll(per_file_s if current is not None else 60.0):
                    if current is None:
                        raise RuntimeError("the fuzz child did not start")
                    out[current] = Outcome("hang", f"no answer within {per_file_s:g} s", per_file_s)
                    start = current + 1
                    break
                try:
                    msg = receive.recv()
                except EOFError:
                    if current is None:
                        start = len(files)
                        break
                    proc.join()
                    out[current] = Outcome("crash", f"exit code {proc.exitcode}", time.perf_counter() - t0)
                    start = current + 1
                    break
                if msg[0] == "start":
                    current, t0 = msg[1], time.perf_counter()
                else:
                    _, i, kind, detail, seconds = msg
                    out[i] = Outcome(kind, detail, seconds)
                    current = None
                    if i == len(files) - 1:
                        start = len(files)
                        break
        finally:
            receive.close()
            if proc.is_alive():
                proc.kill()
            proc.join()
    return [o if o is not None else Outcome("crash", "no outcome", 0.0) for o in out]


def ingest_digest(src: Path, dest: Path, metadata: dict[str, Any], *,
                  ingest_fn: Callable[..., Any] | None = None, **kwargs: Any) -> str:
    """Ingest ``src`` and return a digest of what was stored: rate, length, every channel's samples."""
    import numpy as np

    from app.io import ingest, open_run

    summary = (ingest_fn or ingest)(src, None, metadata, dest, **kwargs)
    h = hashlib.sha256(f"{summary.fs!r} {summary.n_samples} {summary.channels}".encode())
    with open_run(dest) as run:
        for c in run.channels:
            h.update(np.ascontiguousarray(run.read(c), dtype=np.float64).tobytes())
    dest.unlink()
    return h.hexdigest()
