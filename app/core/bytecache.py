"""A small thread-safe in-process LRU cache bounded by the bytes it holds.

The API keeps the encoded answers of immutable results in it (the display
query of a published job's profile: :mod:`app.api.profiles`). Scope: one
process; every API process keeps its own.
"""

from __future__ import annotations

import threading
from collections import OrderedDict
from typing import Generic, TypeVar

__all__ = ["ByteLRU"]

V = TypeVar("V")


class ByteLRU(Generic[V]):
    """Least-recently-used cache of values whose sizes add up to at most ``max_bytes``.

    Parameters
    ----------
    max_bytes : int
        Budget, bytes (>= 0; 0 disables the cache). A value larger than a
        quarter of the budget is not kept.
    """

    def __init__(self, max_bytes: int) -> None:
        if int(max_bytes) != max_bytes or max_bytes < 0:
            raise ValueError(f"max_bytes must be a non-negative integer, got {max_bytes!r}")
        self.max_bytes = int(max_bytes)
        self._items: OrderedDict[str, tuple[V, int]] = OrderedDict()
        self._size = 0
        self._lock = threading.Lock()
        self.hits = 0
        self.misses = 0

    @property
    def size(self) -> int:
        """Bytes held now."""
        return self._size

    def __len__(self) -> int:
        return len(self._items)

    def get(self, key: str) -> V | None:
        """The value of ``key`` (now the most recently used), or None."""
        with self._lock:
            item = self._items.get(key)
            if item is None:
                self.misses += 1
                return None
            self._items.move_to_end(key)
            self.hits += 1
            return item[0]

    def put(self, key: str, value: V, nbytes: int) -> bool:
        """Keep ``value`` of ``nbytes`` under ``key``, dropping the least recently used; whether kept."""
        if nbytes < 0:
            raise ValueError(f"nbytes must be >= 0, got {nbytes}")
        if nbytes > self.max_bytes // 4:
            return False
        with self._lock:
            old = self._items.pop(key, None)
            if old is not None:
                self._size -= old[1]
            self._items[key] = (value, nbytes)
            self._size += nbytes
            while self._size > self.max_bytes:
                _, (_, dropped) = self._items.popitem(last=False)
                self._size -= dropped
            return True

    def clear(self) -> None:
        """Forget everything."""
        with self._lock:
            self._items.clear()
            self._size = 0
