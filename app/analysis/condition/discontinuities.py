"""Known discontinuities of the track near places: switches, crossings, bridges, joints, welds.

Where the track changes abruptly, the dynamic response is high for reasons
that are not a defect of the support (a bridge end, a switch's frog, an
insulated joint, a weld). Recording-car practice labels exceedances there
with the asset — and lets a railway mute an asset type from the work list,
*labelled, never silently dropped*. :func:`assets_at` finds, for each place,
the assets whose extent (a point asset has from = to) lies within
``buffer_m`` of it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["ASSET_TYPES", "AssetHits", "assets_at"]

#: Asset types of the reference data (an import may use others; they are kept as given).
ASSET_TYPES: tuple[str, ...] = ("switch", "crossing", "bridge", "level_crossing", "insulated_joint", "weld", "other")


@dataclass(frozen=True)
class AssetHits:
    """Assets near each place.

    Attributes
    ----------
    place : numpy.ndarray
        int64 place index of each hit.
    asset : numpy.ndarray
        int64 asset index of each hit (ascending within a place).
    distance_m : numpy.ndarray
        Gap between the place's and the asset's extent, m (0 where they overlap).
    """

    place: np.ndarray
    asset: np.ndarray
    distance_m: np.ndarray

    def of(self, place: int) -> np.ndarray:
        """Asset indices near place ``place``."""
        return self.asset[self.place == place]


def _extents(a: object, b: object, names: str) -> tuple[np.ndarray, np.ndarray]:
    x = np.asarray(a, dtype=np.float64)
    y = np.asarray(b, dtype=np.float64)
    if x.ndim != 1 or y.shape != x.shape:
        raise ValueError(f"{names}: must be 1-D of equal length")
    if x.size and not (np.all(np.isfinite(x)) and np.all(np.isfinite(y)) and np.all(y >= x)):
        raise ValueError(f"{names}: must be finite with from <= to")
    return x, y


def assets_at(place_start_m: np.ndarray, place_end_m: np.ndarray, asset_from_m: np.ndarray,
              asset_to_m: np.ndarray, *, buffer_m: float = 20.0) -> AssetHits:
    """The assets within ``buffer_m`` of each place.

    Parameters
    ----------
    place_start_m, place_end_m : numpy.ndarray
        Places' extents on the km axis, m.
    asset_from_m, asset_to_m : numpy.ndarray
        Assets' extents, m (equal for a point asset).
    buffer_m : float
        Largest gap between a place and an asset it is labelled with, m (≥ 0): the filtered
        amplitude smears an abrupt change over some metres, and positions carry alignment residuals.

    Returns
    -------
    AssetHits
        One row per (place, asset) pair, by place then asset.
    """
    if not (np.isfinite(buffer_m) and buffer_m >= 0):
        raise ValueError(f"buffer_m: must be a finite number >= 0, got {buffer_m!r}")
    pa, pb = _extents(place_start_m, place_end_m, "place_start_m, place_end_m")
    aa, ab = _extents(asset_from_m, asset_to_m, "asset_from_m, asset_to_m")
    places, assets, dist = [], [], []
    if pa.size and aa.size:
        order = np.argsort(aa, kind="stable")
        aa_s = aa[order]
        longest = float(np.max(ab - aa))
        for i in range(pa.size):
            lo = np.searchsorted(aa_s, pa[i] - buffer_m - longest, side="left")
            hi = np.searchsorted(aa_s, pb[i] + buffer_m, side="right")
            cand = np.sort(order[lo:hi])
            gap = np.maximum(np.maximum(aa[cand] - pb[i], pa[i] - ab[cand]), 0.0)
            near = gap <= buffer_m
            places.extend([i] * int(near.sum()))
            assets.extend(cand[near].tolist())
            dist.extend(gap[near].tolist())
    return AssetHits(place=np.asarray(places, dtype=np.int64), asset=np.asarray(assets, dtype=np.int64),
                     distance_m=np.asarray(dist, dtype=np.float64))
