"""Profile answers computed once per process and kept in memory.

An answer is computed in a worker thread, at most ``TRACKVKF_PROFILE_CONCURRENCY`` at once
(the limiter), and kept with its gzip encoding in a byte-bounded LRU
(``TRACKVKF_PROFILE_CACHE_BYTES``) under its ETag. Requests for an answer already being
computed in this process wait for that computation instead of repeating it (50 browsers
opening the same map at once compute it once).
"""

from __future__ import annotations

import asyncio
from dataclasses import dataclass, field

import anyio
import anyio.to_thread

from app.core.bytecache import ByteLRU
from app.db.display_arrays import DisplayArrays
from app.db.session import Database
from app.profiles.answer import Computed, compute
from app.profiles.query import ProfileQuery
from app.settings import Settings

__all__ = ["ProfileAnswers"]


@dataclass
class ProfileAnswers:
    """The answers of one API process: kept ones (``cache``), ones being computed (``pending``),
    the limit of concurrent computations and the display arrays they read from."""

    cache: ByteLRU[tuple[bytes, bytes | None]]
    limiter: anyio.CapacityLimiter
    arrays: DisplayArrays | None = None
    pending: dict[str, asyncio.Future[Computed]] = field(default_factory=dict)

    async def get(self, db: Database, settings: Settings, query: ProfileQuery) -> Computed:
        """The answer of ``query``: ``(body, None)`` when too large to keep, else ``(body, (body, gzip))``."""
        kept = self.cache.get(query.etag)
        if kept is not None:
            return kept[0], kept
        return await self._compute_once(db, settings, query)

    async def _compute_once(self, db: Database, settings: Settings, query: ProfileQuery) -> Computed:
        key = query.etag
        running = self.pending.get(key)
        if running is not None:
            try:
                return await asyncio.shield(running)
            except asyncio.CancelledError:
                task = asyncio.current_task()
                if not running.cancelled() or (task is not None and task.cancelling()):
                    raise
                # the request computing it went away (client gone): compute it for this one
                return await self._compute_once(db, settings, query)
        future: asyncio.Future[Computed] = asyncio.get_running_loop().create_future()
        self.pending[key] = future
        try:
            result = await anyio.to_thread.run_sync(
                compute, db, settings, query, self.cache.max_bytes // 4, self.arrays, limiter=self.limiter,
            )
            if result[1] is not None:
                self.cache.put(key, result[1], len(result[1][0]) + len(result[1][1] or b""))
            future.set_result(result)
            return result
        except asyncio.CancelledError:
            future.cancel()
            raise
        except BaseException as exc:
            future.set_exception(exc)
            future.exception()  # retrieved: no "never retrieved" warning when nobody else waited
            raise
        finally:
            del self.pending[key]
