"""Parse untrusted files in a child process with a wall-clock and a memory budget.

The readers check what they can before a third-party parser sees a file
(:mod:`app.io.sources.mdf4_blocks`, :mod:`app.io.sources.tdms_segments`, the
HDF5 tree and extents, Parquet footers …), but libhdf5, pyarrow, asammdf,
npTDMS, pandas and PROJ remain code that a crafted file can drive into a loop
(measured: a flipped byte of an HDF5 attribute kept libhdf5 busy past 10 s),
a crash (a short MDF4 data block segfaulted asammdf before the checks) or a
huge allocation. :func:`run_bounded` runs such a parse in a process forked
from a clean server process (``forkserver``: the parsing libraries already
imported) with

* a wall-clock budget (:class:`ParseBudget`, ``TRACKVKF_PARSE_SECONDS`` plus
  ``file size / TRACKVKF_PARSE_MIN_BYTES_PER_S``): past it the child is killed;
* a memory budget (``TRACKVKF_PARSE_MEMORY_BYTES``): the child's data segment
  (``RLIMIT_DATA``, heap and anonymous mappings) may grow by that much; a
  larger allocation fails inside the child;
* a CPU-time limit (``RLIMIT_CPU``) as a second line, and no core dumps.

Every way the child can fail is answered as :class:`RunFileError` naming
``file`` (a 4xx): over time (:class:`ParseBudgetExceeded`), out of memory, a
crash (a signal), or an exception the parser did not expect (logged with its
traceback). :class:`RunFileError` and :class:`~app.core.diskspace.DiskFullError`
raised in the child are raised again here unchanged.

Callables cannot cross the process boundary; a ``callbacks`` mapping names the
ones the parse needs (the upload's geometry lookup, which reads the
database): the child calls them through the pipe and the parent runs them.
"""

from __future__ import annotations

import logging
import multiprocessing
import os
import signal
import threading
import time
import traceback
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from multiprocessing import popen_forkserver, spawn
from multiprocessing.context import ForkServerProcess
from typing import Any

from app.core.i18n import _
from app.io.errors import RunFileError

__all__ = [
    "ParseBudget",
    "ParseBudgetExceeded",
    "run_bounded",
    "Callback",
    "budget_from",
    "ingest_bounded",
    "parse_geojson_bounded",
    "read_reference_bounded",
    "ingest_upload",
    "parse_geojson_upload",
    "read_reference_upload",
    "warm_up",
]

log = logging.getLogger(__name__)

_CHILD = "app.io._parse_child"
#: Modules the fork server imports once, so that each child starts with them loaded.
PRELOAD = [_CHILD]
_POLL_S = 0.25


@dataclass(frozen=True)
class ParseBudget:
    """What one parse may use.

    Attributes
    ----------
    seconds : float
        Wall-clock time, s (time spent in callbacks in the parent not counted).
    memory_bytes : int
        Growth of the child's data segment, bytes.
    """

    seconds: float
    memory_bytes: int

    @classmethod
    def for_file(cls, file_bytes: int, *, base_s: float, min_bytes_per_s: float, memory_bytes: int) -> ParseBudget:
        """``base_s`` plus the time to parse ``file_bytes`` at ``min_bytes_per_s``."""
        if not (base_s > 0 and min_bytes_per_s > 0 and memory_bytes > 0):
            raise ValueError("base_s, min_bytes_per_s and memory_bytes must be > 0")
        return cls(base_s + max(int(file_bytes), 0) / min_bytes_per_s, int(memory_bytes))


class ParseBudgetExceeded(RunFileError):
    """A parse ran past its wall-clock budget (``field == "file"``)."""


@dataclass(frozen=True)
class Callback:
    """Placeholder for a parent-side callable in the arguments of :func:`run_bounded`."""

    name: str


class _RemoteCall:
    """In the child: calls the parent's callable ``name`` through the pipe."""

    def __init__(self, conn: Any, name: str) -> None:
        self._conn, self._name = conn, name

    def __call__(self, *args: Any) -> Any:
        self._conn.send(("call", self._name, args))
        return self._conn.recv()[1]


def _data_bytes() -> int:
    """This process's data segment (``VmData``), bytes."""
    with open("/proc/self/status", encoding="ascii") as fh:
        for line in fh:
            if line.startswith("VmData:"):
                return int(line.split()[1]) * 1024
    return 0  # pragma: no cover - Linux has it


def _limit(memory_bytes: int, cpu_s: float) -> None:
    import resource

    base = _data_bytes()
    if base:
        resource.setrlimit(resource.RLIMIT_DATA, (base + memory_bytes, base + memory_bytes))
    cpu = max(int(cpu_s) + 1, 2)
    resource.setrlimit(resource.RLIMIT_CPU, (cpu, cpu + 5))
    resource.setrlimit(resource.RLIMIT_CORE, (0, 0))


def _resolve(fn: Callable[..., Any] | str) -> Callable[..., Any]:
    if callable(fn):
        return fn
    import importlib

    module, _sep, name = fn.partition(":")
    return getattr(importlib.import_module(module), name)


def _child(conn: Any, fn: Callable[..., Any] | str, args: tuple, kwargs: dict, memory_bytes: int,
           cpu_s: float) -> None:
    from app.core.diskspace import DiskFullError

    try:
        _limit(memory_bytes, cpu_s)
        fn = _resolve(fn)
        kwargs = {k: _RemoteCall(conn, v.name) if isinstance(v, Callback) else v for k, v in kwargs.items()}
        msg: tuple = ("ok", fn(*args, **kwargs))
    except RunFileError as exc:
        msg = ("raise", exc)
    except DiskFullError as exc:  # not picklable as it is: rebuilt in the parent
        msg = ("disk", str(exc.filename), exc.message)
    except MemoryError:
        msg = ("memory", "")
    except BaseException as exc:  # noqa: BLE001 - reported to the parent, with its traceback
        msg = ("bug", f"{type(exc).__name__}: {str(exc)[:300]}", traceback.format_exc()[-4000:])
    try:
        conn.send(msg)
    except Exception as exc:  # noqa: BLE001 - e.g. a result that cannot be pickled
        conn.send(("bug", f"cannot return the result: {type(exc).__name__}: {exc}", ""))
    conn.close()


def _forget_inherited_fork_server() -> None:
    """In a process forked from one that ran a fork server: start a fork server of its own.

    The fork server is a child of the process that started it; a plain fork
    inherits the bookkeeping (its pid cannot be waited for here, its lock may
    be held by a thread that does not exist here) and would fail on first use.
    """
    from multiprocessing import forkserver

    server = getattr(forkserver, "_forkserver", None)
    if server is None or getattr(server, "_forkserver_pid", None) is None:
        return
    alive = getattr(server, "_forkserver_alive_fd", None)
    if alive is not None:
        try:
            os.close(alive)  # this copy of the "alive" pipe would keep the parent's server running
        except OSError:
            pass
    server._forkserver_pid = None
    server._forkserver_address = None
    server._forkserver_alive_fd = None
    server._lock = threading.Lock()


os.register_at_fork(after_in_child=_forget_inherited_fork_server)


_PREP_LOCK = threading.Lock()


def _preparation_without_main(name: str) -> dict[str, Any]:
    data = _ORIGINAL_PREPARATION(name)
    data.pop("init_main_from_path", None)
    data.pop("init_main_from_name", None)
    return data


_ORIGINAL_PREPARATION = spawn.get_preparation_data


class _Popen(popen_forkserver.Popen):
    """The fork server's launcher, minus re-running the parent's main module in the child.

    multiprocessing makes a fork-server child import the parent's ``__main__``
    (the ``trackvkf`` script, pytest …): seconds per child for nothing, since
    the child's code is importable. The preparation data leave it out.
    """

    def _launch(self, process_obj: Any) -> None:
        with _PREP_LOCK:
            spawn.get_preparation_data = _preparation_without_main
            try:
                super()._launch(process_obj)
            finally:
                spawn.get_preparation_data = _ORIGINAL_PREPARATION


class _ParseProcess(ForkServerProcess):
    @staticmethod
    def _Popen(process_obj: Any) -> _Popen:
        return _Popen(process_obj)


def _context() -> Any:
    ctx = multiprocessing.get_context("forkserver")
    ctx.set_forkserver_preload(PRELOAD)  # no effect once this process's fork server runs
    return ctx


def run_bounded(
    fn: Callable[..., Any] | str,
    args: tuple = (),
    kwargs: Mapping[str, Any] | None = None,
    *,
    budget: ParseBudget,
    what: str,
    callbacks: Mapping[str, Callable[..., Any]] | None = None,
) -> Any:
    """``fn(*args, **kwargs)`` in a child process within ``budget``.

    Parameters
    ----------
    fn : callable or str
        A module-level function, or ``"module:function"`` (imported in the
        child only); its arguments and result are pickled.
    args, kwargs
        Its arguments; a :class:`Callback` value in ``kwargs`` becomes a
        callable in the child that runs ``callbacks[name]`` here.
    budget : ParseBudget
        Time and memory.
    what : str
        What is parsed, for messages (``"the MDF4 file"``).
    callbacks : mapping, optional
        Name → callable run in this process on the child's request.

    Returns
    -------
    Any
        What ``fn`` returned.

    Raises
    ------
    RunFileError
        Raised by ``fn``, or ``field == "file"`` when the child ran out of
        time (:class:`ParseBudgetExceeded`) or memory, crashed, or raised
        anything else.
    DiskFullError
        Raised by ``fn``.
    """
    callbacks = dict(callbacks or {})
    ctx = _context()
    parent, child = ctx.Pipe(duplex=True)
    proc = _ParseProcess(
        target=_child,
        args=(child, fn, tuple(args), dict(kwargs or {}), budget.memory_bytes, budget.seconds * 2),
        daemon=True,
    )
    proc.start()
    child.close()
    deadline = time.monotonic() + budget.seconds
    try:
        while True:
            left = deadline - time.monotonic()
            if left <= 0:
                raise ParseBudgetExceeded(
                    "file", _("reading {what} took longer than its budget of {seconds:.0f} s (TRACKVKF_PARSE_SECONDS, TRACKVKF_PARSE_MIN_BYTES_PER_S): refused as a file the parser cannot finish", what=what, seconds=budget.seconds)
                )
            if not parent.poll(min(left, _POLL_S)):
                if not proc.is_alive() and not parent.poll(0):
                    raise _crashed(proc, what)
                continue
            try:
                msg = parent.recv()
            except EOFError:
                proc.join(5)
                raise _crashed(proc, what) from None
            if msg[0] == "call":
                # the parent's own failure (the database …) is raised here, not blamed on the file
                started = time.monotonic()
                parent.send(("ok", callbacks[msg[1]](*msg[2])))
                deadline += time.monotonic() - started
                continue
            return _result(msg, budget, what)
    finally:
        parent.close()
        if proc.is_alive():
            proc.kill()
        proc.join()


def _result(msg: tuple, budget: ParseBudget, what: str) -> Any:
    kind = msg[0]
    if kind == "ok":
        return msg[1]
    if kind == "raise":
        raise msg[1]
    if kind == "disk":
        from app.core.diskspace import DiskFullError

        raise DiskFullError(msg[1], msg[2])
    if kind == "memory":
        raise RunFileError(
            "file", _("reading {what} needs more than {mib:.0f} MiB of memory (TRACKVKF_PARSE_MEMORY_BYTES)", what=what, mib=budget.memory_bytes / 2**20)
        )
    log.error("the parser failed on %s: %s\n%s", what, msg[1], msg[2] if len(msg) > 2 else "")
    raise RunFileError("file", _("{what} cannot be read: {error}", what=what, error=msg[1]))


def _crashed(proc: Any, what: str) -> RunFileError:
    code = proc.exitcode
    if code is not None and code < 0 and -code in (signal.SIGXCPU, signal.SIGKILL):
        return ParseBudgetExceeded("file", _("reading {what} used more CPU time than its budget", what=what))
    name = signal.Signals(-code).name if code is not None and code < 0 else f"exit code {code}"
    log.error("the parser crashed on %s (%s)", what, name)
    return RunFileError("file", _("{what} crashed the parser ({name}): refused as corrupt", what=what, name=name))




def budget_from(settings: Any, file_bytes: int) -> ParseBudget:
    """The budget of a ``file_bytes`` file under the service settings (``TRACKVKF_PARSE_*``)."""
    return ParseBudget.for_file(
        file_bytes,
        base_s=settings.parse_seconds,
        min_bytes_per_s=settings.parse_min_bytes_per_s,
        memory_bytes=settings.parse_memory_bytes,
    )


def ingest_bounded(src: Any, fmt: str | None, metadata: Any, dest: Any, *, budget: ParseBudget,
                   geometry: Any = None, **kwargs: Any) -> Any:
    """:func:`app.io.ingest.ingest` in a child process within ``budget`` (see :func:`run_bounded`).

    ``geometry`` may be a lookup ``(line_id, track) -> LineGeometry | None``
    (run here, in the parent: it may read the database) or a geometry.
    """
    callbacks = {}
    if callable(geometry):
        callbacks["geometry"] = geometry
        geometry = Callback("geometry")
    return run_bounded(f"{_CHILD}:ingest_file", (src, fmt, metadata, dest), {**kwargs, "geometry": geometry},
                       budget=budget, what=_("the {format} file", format=fmt) if fmt else _("the run file"), callbacks=callbacks)


def parse_geojson_bounded(data: bytes, *, budget: ParseBudget) -> Any:
    """:func:`app.io.geometry.parse_geojson` in a child process within ``budget``."""
    return run_bounded(f"{_CHILD}:parse_geojson_file", (data,), budget=budget, what=_("the GeoJSON file"))


def read_reference_bounded(data: bytes, kind: str, fmt: str | None, filename: str | None, *,
                           budget: ParseBudget) -> Any:
    """:func:`app.io.reference.read_reference` in a child process within ``budget``."""
    return run_bounded(f"{_CHILD}:read_reference_file", (data, kind, fmt, filename), budget=budget,
                       what=_("the {kind} file", kind=kind))


def ingest_upload(settings: Any, src: Any, fmt: str | None, metadata: Any, dest: Any, **kwargs: Any) -> Any:
    """Ingest an uploaded file: bounded in a child process unless ``settings.parse_isolated`` is off."""
    from pathlib import Path

    if not settings.parse_isolated:
        from app.io.ingest import ingest

        return ingest(src, fmt, metadata, dest, **kwargs)
    budget = budget_from(settings, Path(src).stat().st_size)
    return ingest_bounded(src, fmt, metadata, dest, budget=budget, **kwargs)


def parse_geojson_upload(settings: Any, data: bytes) -> Any:
    """Parse an uploaded GeoJSON document: bounded unless ``settings.parse_isolated`` is off."""
    if not settings.parse_isolated:
        from app.io.geometry import parse_geojson

        return parse_geojson(data)
    return parse_geojson_bounded(data, budget=budget_from(settings, len(data)))


def read_reference_upload(settings: Any, data: bytes, kind: str, fmt: str | None, filename: str | None) -> Any:
    """Parse an uploaded reference file: bounded unless ``settings.parse_isolated`` is off."""
    if not settings.parse_isolated:
        from app.io.reference import read_reference

        return read_reference(data, kind, fmt, filename)  # type: ignore[arg-type]
    return read_reference_bounded(data, kind, fmt, filename, budget=budget_from(settings, len(data)))


def warm_up() -> None:
    """Start this process's fork server in the background (the first parse then need not wait).

    Starting it imports the parsing libraries once (seconds); without this the
    first upload after a start pays for it.
    """

    def start() -> None:
        try:
            _context()
            from multiprocessing import forkserver

            forkserver.ensure_running()
        except Exception:  # noqa: BLE001 - the first parse starts it again and reports
            log.warning("could not start the parse fork server in advance", exc_info=True)

    threading.Thread(target=start, name="parse-forkserver", daemon=True).start()
