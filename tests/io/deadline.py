"""Run a call in a forked child with a hard time limit: a hang fails the test instead of CI."""

from __future__ import annotations

import multiprocessing
import pickle
import traceback
from collections.abc import Callable
from typing import Any

import pytest

__all__ = ["call_with_deadline"]


def _child(conn, fn: Callable[..., Any], args: tuple, kwargs: dict) -> None:  # noqa: ANN001
    try:
        result: tuple[bool, Any] = (True, fn(*args, **kwargs))
    except BaseException as exc:  # noqa: BLE001 - everything goes back to the test
        result = (False, exc)
    try:
        conn.send(result)
    except (pickle.PicklingError, TypeError, AttributeError):
        conn.send((False, RuntimeError(f"{result[1]!r} (not picklable):\n{traceback.format_exc()}")))
    conn.close()


def call_with_deadline(fn: Callable[..., Any], *args: Any, seconds: float, **kwargs: Any) -> Any:
    """``fn(*args, **kwargs)`` in a forked child; fail the test if it runs longer than ``seconds``.

    The child's exception (if any) is raised here; a child killed by a signal
    (a crash in C code) fails the test too.
    """
    ctx = multiprocessing.get_context("fork")
    receive, send = ctx.Pipe(duplex=False)
    proc = ctx.Process(target=_child, args=(send, fn, args, kwargs), daemon=True)
    proc.start()
    send.close()
    try:
        if not receive.poll(seconds):
            proc.kill()
            proc.join()
            pytest.fail(f"{getattr(fn, '__name__', fn)} did not return within {seconds:g} s (a hang)")
        try:
            ok, value = receive.recv()
        except EOFError:
            proc.join()
            pytest.fail(f"{getattr(fn, '__name__', fn)} crashed (exit code {proc.exitcode})")
    finally:
        receive.close()
        proc.join(5)
        if proc.is_alive():
            proc.kill()
            proc.join()
    if ok:
        return value
    raise value
