"""The asset register's size limit (light: the settings group names it without the reader)."""

from __future__ import annotations

__all__ = ["MAX_ASSETS"]

#: Largest number of assets in one file (a national register of one line is far below); the reader
#: refuses more, and the import's row limit is at most this
MAX_ASSETS = 200_000
