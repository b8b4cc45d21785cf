"""Logging set-up shared by the API, the worker and the CLI: plain text or JSON lines.

``TRACKVKF_LOG_FORMAT=json`` writes one JSON object per line (for a log
collector): ``{"time": "2026-12-01T10:00:00.123Z", "level": "INFO", "logger":
"worker.runner", "message": "...", "pid": 123}`` plus ``"exception"`` (the
formatted traceback) when there is one. uvicorn's own loggers (server and
access log) get the same format.
"""

from __future__ import annotations

import datetime as dt
import json
import logging
import sys

__all__ = ["configure_logging", "JsonFormatter", "LOG_FORMATS"]

_FORMAT = "%(asctime)s %(levelname)-7s %(name)s: %(message)s"
#: values of ``TRACKVKF_LOG_FORMAT``
LOG_FORMATS = ("text", "json")
_UVICORN_LOGGERS = ("uvicorn", "uvicorn.error", "uvicorn.access")


class JsonFormatter(logging.Formatter):
    """One JSON object per record: time (UTC, ms), level, logger, message, pid[, exception]."""

    def format(self, record: logging.LogRecord) -> str:
        stamp = dt.datetime.fromtimestamp(record.created, dt.UTC)
        out = {
            "time": stamp.strftime("%Y-%m-%dT%H:%M:%S.") + f"{stamp.microsecond // 1000:03d}Z",
            "level": record.levelname,
            "logger": record.name,
            "message": record.getMessage(),
            "pid": record.process,
        }
        if record.exc_info:
            out["exception"] = self.formatException(record.exc_info)
        elif record.exc_text:
            out["exception"] = record.exc_text
        return json.dumps(out, ensure_ascii=False, default=str)


def _formatter(fmt: str) -> logging.Formatter:
    if fmt not in LOG_FORMATS:
        raise ValueError(f"fmt: log format must be one of {', '.join(LOG_FORMATS)}, got {fmt!r}")
    return JsonFormatter() if fmt == "json" else logging.Formatter(_FORMAT)


def configure_logging(level: str | int = "INFO", fmt: str = "text") -> None:
    """Send the ``app`` and ``worker`` loggers to stderr at ``level``, as text or JSON lines.

    Parameters
    ----------
    level : str or int
        A :mod:`logging` level name (``"INFO"``, ``"DEBUG"``, ...) or number.
    fmt : {"text", "json"}
        Plain text lines, or one JSON object per line (uvicorn's loggers too).

    Calling it again only changes the level and the format; handlers are not duplicated.
    """
    formatter = _formatter(fmt)
    if isinstance(level, str):
        numeric = logging.getLevelName(level.upper())
        if not isinstance(numeric, int):
            raise ValueError(f"level: unknown logging level {level!r}")
        level = numeric
    for name in ("app", "worker"):
        logger = logging.getLogger(name)
        logger.setLevel(level)
        ours = [h for h in logger.handlers if getattr(h, "_trackvkf", False)]
        if not ours:
            handler = logging.StreamHandler(sys.stderr)
            handler._trackvkf = True  # type: ignore[attr-defined]
            logger.addHandler(handler)
            ours = [handler]
        for handler in ours:
            handler.setFormatter(formatter)
        logger.propagate = False
    if fmt == "json":
        for name in _UVICORN_LOGGERS:
            for handler in logging.getLogger(name).handlers:
                handler.setFormatter(formatter)
