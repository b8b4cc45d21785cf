"""A small in-process sliding-window rate limiter.

Scope: one API process. Several uvicorn workers or API replicas each keep
their own counts, so the effective limit is ``limit × processes``; put a
shared limiter (reverse proxy, Redis) in front when that matters.
"""

from __future__ import annotations

import math
import threading
import time
from collections import OrderedDict, deque
from collections.abc import Callable

__all__ = ["RateLimiter"]


class RateLimiter:
    """At most ``limit`` hits per key within any ``window_s`` seconds.

    Parameters
    ----------
    limit : int
        Hits allowed per window (>= 1).
    window_s : float
        Window length, s (> 0).
    max_keys : int
        Keys remembered at most; the least recently used key is forgotten
        beyond that (bounded memory under a flood of distinct keys).
    clock : callable
        Monotonic time source, s (tests may pass their own).
    """

    def __init__(
        self,
        limit: int,
        window_s: float,
        *,
        max_keys: int = 10_000,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        if int(limit) != limit or limit < 1:
            raise ValueError(f"limit must be a positive integer, got {limit!r}")
        if not (math.isfinite(window_s) and window_s > 0):
            raise ValueError(f"window_s must be > 0 s, got {window_s!r}")
        if int(max_keys) != max_keys or max_keys < 1:
            raise ValueError(f"max_keys must be a positive integer, got {max_keys!r}")
        self.limit = int(limit)
        self.window_s = float(window_s)
        self.max_keys = int(max_keys)
        self._clock = clock
        self._hits: OrderedDict[str, deque[float]] = OrderedDict()
        self._lock = threading.Lock()

    def hit(self, key: str) -> float | None:
        """Count a hit of ``key``.

        Returns
        -------
        float or None
            None if the hit is allowed (and counted); else the seconds until
            the next hit would be allowed (the hit is not counted).
        """
        now = self._clock()
        with self._lock:
            hits = self._hits.get(key)
            if hits is None:
                hits = deque()
                self._hits[key] = hits
                while len(self._hits) > self.max_keys:
                    self._hits.popitem(last=False)
            else:
                self._hits.move_to_end(key)
            while hits and hits[0] <= now - self.window_s:
                hits.popleft()
            if len(hits) >= self.limit:
                return max(hits[0] + self.window_s - now, 0.001)
            hits.append(now)
            return None

    def reset(self, key: str) -> None:
        """Forget the hits of ``key``."""
        with self._lock:
            self._hits.pop(key, None)
