"""Logging set-up shared by the API, the worker and the CLI."""

from __future__ import annotations

import logging
import sys

__all__ = ["configure_logging"]

_FORMAT = "%(asctime)s %(levelname)-7s %(name)s: %(message)s"


def configure_logging(level: str | int = "INFO") -> None:
    """Send the ``app`` and ``worker`` loggers to stderr at ``level``.

    Parameters
    ----------
    level : str or int
        A :mod:`logging` level name (``"INFO"``, ``"DEBUG"``, ...) or number.

    Calling it again only changes the level; handlers are not duplicated.
    """
    if isinstance(level, str):
        numeric = logging.getLevelName(level.upper())
        if not isinstance(numeric, int):
            raise ValueError(f"level: unknown logging level {level!r}")
        level = numeric
    for name in ("app", "worker"):
        logger = logging.getLogger(name)
        logger.setLevel(level)
        if not any(getattr(h, "_trackvkf", False) for h in logger.handlers):
            handler = logging.StreamHandler(sys.stderr)
            handler.setFormatter(logging.Formatter(_FORMAT))
            handler._trackvkf = True  # type: ignore[attr-defined]
            logger.addHandler(handler)
        logger.propagate = False
