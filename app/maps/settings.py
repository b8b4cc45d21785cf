"""The map page's settings group (``TRACKVKF_MAP_TILE_*``)."""

from __future__ import annotations

from pydantic import Field

from app.core.config import SettingsGroup

__all__ = ["MapSettings"]


class MapSettings(SettingsGroup):
    """Map: the basemap under the line geometry.

    Attributes
    ----------
    map_tile_url : str, optional
        Raster tile URL template (``https://tiles.example/{z}/{x}/{y}.png``) of
        a basemap under the map page's line geometry. Default: none (the page
        draws the geometry alone and requests nothing outside the server).
    map_tile_attribution : str
        Attribution text shown with the basemap.
    """

    map_tile_url: str | None = Field(default=None, max_length=500)
    map_tile_attribution: str = Field(default="", max_length=300)
