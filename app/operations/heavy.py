"""Heavy work of an API process (validating and converting an upload) kept from starving its reads.

An API process serves everything from one event loop and one thread pool, under one GIL.
Converting an upload (reading and validating the recorder file, writing the canonical HDF5
file: :func:`app.io.ingest`) is CPU work that holds the GIL for long stretches (h5py calls do
not release it). With 20 uploads converting at once in the default thread pool, 20 threads
took turns with the event loop and with the threads answering reads, so a map read waited
seconds for its turns (issue 24: p99 4.7 s with 20 uploads streaming in).

:func:`run_heavy` runs such work in the thread pool under the process's *heavy-work limiter*
(``TRACKVKF_UPLOAD_INGEST_CONCURRENCY`` conversions at once per process, default 1; the
others wait their turn without a thread), so the event loop and the reads keep at least their
share of the GIL whatever the number of uploads. Receiving the bytes (multipart parsing,
hashing, writing 1 MiB blocks) is not limited: it is cheap and releases the GIL.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TypeVar

import anyio
import anyio.to_thread

__all__ = ["install_heavy_limiter", "run_heavy"]

T = TypeVar("T")


def install_heavy_limiter(app, concurrency: int) -> None:
    """Give the app its heavy-work limiter (``concurrency`` >= 1 at once)."""
    if concurrency < 1:
        raise ValueError(f"concurrency must be >= 1, got {concurrency}")
    app.state.heavy_limiter = anyio.CapacityLimiter(concurrency)


async def run_heavy(app, fn: Callable[[], T]) -> T:
    """Run ``fn()`` in a worker thread under the app's heavy-work limiter; its result."""
    limiter = getattr(app.state, "heavy_limiter", None)
    if limiter is None:  # an app built without create_app (tests): one at a time
        install_heavy_limiter(app, 1)
        limiter = app.state.heavy_limiter
    return await anyio.to_thread.run_sync(fn, limiter=limiter)
