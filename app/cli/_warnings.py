"""Warnings of the processing engine on the command line: one line each, above the progress bar.

Python prints a warning with its source line (``vkf.py:188: VKFWarning: ... warnings.warn(``)
straight into the terminal, through the progress bar. During ``trackvkf process`` each distinct
warning is written once as ``warning: VKFWarning: <message>`` above the bar (repeats counted at
the end) and all of them go into ``meta.json``.
"""

from __future__ import annotations

import contextlib
import warnings
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field

__all__ = ["EngineWarnings", "engine_warnings"]

@dataclass
class EngineWarnings:
    """The distinct warnings seen: ``(category, message)`` → count, in order of appearance."""

    counts: dict[tuple[str, str], int] = field(default_factory=dict)

    def as_list(self) -> list[dict[str, object]]:
        """JSON-ready: ``[{"category", "message", "count"}]``."""
        return [{"category": c, "message": m, "count": n} for (c, m), n in self.counts.items()]


@contextlib.contextmanager
def engine_warnings(write: Callable[[str], None]) -> Iterator[EngineWarnings]:
    """Route warnings raised inside the block to ``write`` (e.g. ``tqdm.write``), once each.

    Parameters
    ----------
    write : callable
        Prints one line without disturbing the progress bar.
    """
    seen = EngineWarnings()

    def show(message, category, filename, lineno, file=None, line=None) -> None:  # noqa: ARG001
        key = (category.__name__, str(message))
        seen.counts[key] = seen.counts.get(key, 0) + 1
        if seen.counts[key] == 1:
            write(f"warning: {key[0]}: {key[1]}")

    with warnings.catch_warnings():
        warnings.simplefilter("always")
        warnings.showwarning = show
        yield seen
    repeated = [(k, n) for k, n in seen.counts.items() if n > 1]
    for (category, message), n in repeated:
        write(f"warning: {category} repeated {n} times in all: {message[:80]}")
