"""A synthetic line geometry: straights and circular curves with km stations.

The line is laid out in a projected CRS (default ETRS89 / UTM 32N, EPSG:25832,
around 9° E 50° N) as alternating straights and curves (radius 600–3000 m,
left and right), with a vertex every ``vertex_spacing_m`` and the line km at
every vertex equal to the distance along it (no km jumps). Written as GeoJSON
in that CRS (:func:`geometry_geojson`), it is what :mod:`app.io.geometry`
imports.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from app.io.geometry import LineGeometry

__all__ = ["DEFAULT_CRS", "synthetic_line", "geometry_geojson", "write_geometry"]

#: CRS the synthetic line is laid out in (ETRS89 / UTM zone 32N).
DEFAULT_CRS = "EPSG:25832"
_ORIGIN = (512_000.0, 5_540_000.0)


def _layout(length_m: float, rng: np.random.Generator, step: float) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (m) of alternating straights and arcs covering ``length_m``."""
    heading = float(rng.uniform(0.0, 2.0 * math.pi))
    x, y = [0.0], [0.0]
    done = 0.0
    curve = False
    while done < length_m:
        seg = float(rng.uniform(400.0, 1500.0)) if not curve else float(rng.uniform(300.0, 900.0))
        radius = float(rng.uniform(600.0, 3000.0)) * (1 if rng.random() < 0.5 else -1)
        n = max(int(math.ceil(seg / step)), 1)
        ds = seg / n
        for _ in range(n):
            if curve:
                heading += ds / radius
            x.append(x[-1] + ds * math.cos(heading))
            y.append(y[-1] + ds * math.sin(heading))
        done += seg
        curve = not curve
    xa, ya = np.array(x), np.array(y)
    chain = np.concatenate(([0.0], np.cumsum(np.hypot(np.diff(xa), np.diff(ya)))))
    keep = chain < length_m - 1e-6
    end_x = np.interp(length_m, chain, xa)
    end_y = np.interp(length_m, chain, ya)
    return np.append(xa[keep], end_x), np.append(ya[keep], end_y)


def synthetic_line(
    km_from: float,
    km_to: float,
    *,
    seed: int = 0,
    line_id: str = "SIM",
    track: str = "1",
    crs: str = DEFAULT_CRS,
    vertex_spacing_m: float = 20.0,
) -> tuple[LineGeometry, dict[str, Any]]:
    """A random line geometry covering ``km_from … km_to``.

    Parameters
    ----------
    km_from, km_to : float
        Km range to cover, km (``km_from < km_to``).
    seed : int
        Seed of the layout.
    line_id, track : str
        Ids written to the feature.
    crs : str
        Projected CRS (metres) of the layout and of the GeoJSON.
    vertex_spacing_m : float
        Distance between vertices, m.

    Returns
    -------
    geometry : LineGeometry
        The line as :mod:`app.io.geometry` holds it (WGS84).
    geojson : dict
        The GeoJSON FeatureCollection in ``crs`` (what an operator would import).
    """
    if not (math.isfinite(km_from) and math.isfinite(km_to) and km_from < km_to):
        raise ValueError(f"need km_from < km_to, got {km_from!r}, {km_to!r}")
    if not vertex_spacing_m > 0:
        raise ValueError(f"vertex_spacing_m must be > 0 m, got {vertex_spacing_m!r}")
    rng = np.random.default_rng([int(seed), 19])
    x, y = _layout(1000.0 * (km_to - km_from), rng, vertex_spacing_m)
    chain = np.concatenate(([0.0], np.cumsum(np.hypot(np.diff(x), np.diff(y)))))
    km = km_from + chain / 1000.0
    ex, ny = x + _ORIGIN[0], y + _ORIGIN[1]
    doc = geometry_geojson(ex, ny, km, line_id=line_id, track=track, crs=crs)
    from app.io.geometry import parse_geojson

    return parse_geojson(doc)[0], doc


def geometry_geojson(
    x: np.ndarray, y: np.ndarray, km: np.ndarray, *, line_id: str, track: str, crs: str
) -> dict[str, Any]:
    """A GeoJSON FeatureCollection of one LineString with km stations, in ``crs``."""
    return {
        "type": "FeatureCollection",
        "crs": {"type": "name", "properties": {"name": crs}},
        "features": [
            {
                "type": "Feature",
                "properties": {
                    "line_id": line_id,
                    "track": track,
                    "km": [round(float(k), 6) for k in km],
                },
                "geometry": {
                    "type": "LineString",
                    "coordinates": [
                        [round(float(a), 3), round(float(b), 3)] for a, b in zip(x, y, strict=True)
                    ],
                },
            }
        ],
    }


def write_geometry(path: Path | str, geojson: dict[str, Any]) -> Path:
    """Write a GeoJSON document; returns the path."""
    path = Path(path)
    path.write_text(json.dumps(geojson), encoding="utf-8")
    return path
