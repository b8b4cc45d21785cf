"""The asset imports' settings group (``TRACKVKF_ASSETS_IMPORT_*``, :mod:`app.assets.service`)."""

from __future__ import annotations

from pydantic import Field

from app.assets.limits import MAX_ASSETS
from app.core.config import SettingsGroup

__all__ = ["AssetSettings"]


class AssetSettings(SettingsGroup):
    """Assets: the limits and batches of an asset import.

    Attributes
    ----------
    assets_import_max_rows : int
        Most assets one import may write (default 200 000, the reader's limit); more: 413.
    assets_import_max_lines : int
        Most (line, track) pairs one import may replace (default 1000); more: 413. The
        transaction that makes an import live writes one row per pair.
    assets_import_batch_rows : int
        Rows an import writes (and replaced rows it deletes) per transaction: the longest it
        holds the write lock (2000 rows: ≈ 0.03 s on SQLite).
    """

    assets_import_max_rows: int = Field(default=MAX_ASSETS, ge=1, le=MAX_ASSETS)
    assets_import_max_lines: int = Field(default=1000, ge=1, le=100_000)
    assets_import_batch_rows: int = Field(default=2000, ge=100, le=100_000)
