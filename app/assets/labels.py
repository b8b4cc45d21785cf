"""Labels of the places on known discontinuities, and the muting of asset types from the list.

Where the track changes abruptly (a bridge end, a switch's frog, an insulated joint) the
response is high for reasons that are not a defect of the support: each place is labelled
with the assets within ``TRACKVKF_PLACES_ASSET_BUFFER_M`` of it
(:func:`app.analysis.condition.discontinuities.assets_at`), and a place on an asset of a type
in ``TRACKVKF_PLACES_MUTED_ASSET_TYPES`` is **muted**: still listed, labelled with the reason,
never silently dropped.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from sqlalchemy.orm import Session

from app.analysis.condition.discontinuities import ASSET_TYPES
from app.db import assets_crud

__all__ = ["MAX_LABELS_PER_PLACE", "PlaceAssets", "muted_types", "label_places"]

#: The most assets a place is labelled with; the rest are counted (``assets_more``).
MAX_LABELS_PER_PLACE = 25


@dataclass(frozen=True)
class PlaceAssets:
    """The assets on one place (``{"id", "type", "km", "name"}``, by km, at most
    :data:`MAX_LABELS_PER_PLACE`), how many more there are, and whether they mute it."""

    assets: list[dict[str, Any]] = field(default_factory=list)
    assets_more: int = 0
    muted: bool = False
    muted_reason: str | None = None


def muted_types(settings: Any) -> tuple[str, ...]:
    """``TRACKVKF_PLACES_MUTED_ASSET_TYPES`` as a tuple of type names.

    Raises
    ------
    ValueError
        Naming the setting and the unknown type.
    """
    raw = getattr(settings, "places_muted_asset_types", "") or ""
    out = tuple(t.strip() for t in raw.split(",") if t.strip())
    for t in out:
        if t not in ASSET_TYPES:
            raise ValueError(f"TRACKVKF_PLACES_MUTED_ASSET_TYPES: {t!r} is not one of {', '.join(ASSET_TYPES)}")
    return out


def label_places(session: Session, settings: Any, line_id: str, track: str, km_from: Sequence[float],
                 km_to: Sequence[float]) -> list[PlaceAssets]:
    """The assets on each place of a line and track, and whether they mute it.

    Parameters
    ----------
    session : Session
    settings : Settings
        ``places_asset_buffer_m`` (m) and ``places_muted_asset_types``.
    line_id, track : str
    km_from, km_to : sequence of float
        The places' extents, km (equal length).

    Returns
    -------
    list of PlaceAssets
        One per place, in the given order.
    """
    a = np.asarray(km_from, dtype=np.float64)
    b = np.asarray(km_to, dtype=np.float64)
    if a.shape != b.shape or a.ndim != 1:
        raise ValueError("km_from, km_to: must be 1-D of equal length")
    mute = sorted(set(muted_types(settings)))
    if not a.size:
        return []
    extent = assets_crud.max_extent_km(session, line_id, track)
    if extent is None:
        return [PlaceAssets() for _ in range(a.size)]
    buffer_km = float(getattr(settings, "places_asset_buffer_m", 20.0)) / 1000.0
    if not (np.isfinite(buffer_km) and buffer_km >= 0):
        raise ValueError(f"places_asset_buffer_m: must be a finite number >= 0, got {buffer_km * 1000.0!r}")
    out = []
    for lo, hi in zip(np.minimum(a, b) - buffer_km, np.maximum(a, b) + buffer_km, strict=True):
        # one indexed range query per place of the page (never the line's whole register), capped
        near, total = assets_crud.assets_near(session, line_id, track, float(lo), float(hi), extent,
                                              limit=MAX_LABELS_PER_PLACE)
        on = {x.type for x in near if x.type in mute}
        if total > len(near):  # a muted type beyond the cap still mutes the place
            on |= {t for t in mute if t not in on and assets_crud.assets_near(
                session, line_id, track, float(lo), float(hi), extent, limit=1, types=(t,))[0]}
        on_sorted = sorted(on)
        out.append(PlaceAssets(
            assets=[{"id": x.id, "type": x.type, "km": x.km, "name": x.name} for x in near],
            assets_more=total - len(near),
            muted=bool(on_sorted),
            muted_reason=(f"at {', '.join(t.replace('_', ' ') for t in on_sorted)} (TRACKVKF_PLACES_MUTED_ASSET_TYPES)"
                          if on_sorted else None),
        ))
    return out
