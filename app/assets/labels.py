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

from app.analysis.condition.discontinuities import ASSET_TYPES, assets_at
from app.db import assets_crud

__all__ = ["PlaceAssets", "muted_types", "label_places"]


@dataclass(frozen=True)
class PlaceAssets:
    """The assets on one place (``{"id", "type", "km", "name"}``, by km) and whether that mutes it."""

    assets: list[dict[str, Any]] = field(default_factory=list)
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
    mute = set(muted_types(settings))
    if not a.size:
        return []
    assets = assets_crud.line_assets(session, line_id, track)
    if not assets:
        return [PlaceAssets() for _ in range(a.size)]
    lo = np.array([x.km for x in assets]) * 1000.0
    hi = np.array([x.km if x.km_to is None else x.km_to for x in assets]) * 1000.0
    hits = assets_at(np.minimum(a, b) * 1000.0, np.maximum(a, b) * 1000.0, lo, hi,
                     buffer_m=float(getattr(settings, "places_asset_buffer_m", 20.0)))
    out = []
    for i in range(a.size):
        near = [assets[j] for j in hits.of(i).tolist()]
        near.sort(key=lambda x: (x.km, x.id))
        on = sorted({x.type for x in near if x.type in mute})
        out.append(PlaceAssets(
            assets=[{"id": x.id, "type": x.type, "km": x.km, "name": x.name} for x in near],
            muted=bool(on),
            muted_reason=(f"at {', '.join(t.replace('_', ' ') for t in on)} (TRACKVKF_PLACES_MUTED_ASSET_TYPES)"
                          if on else None),
        ))
    return out
