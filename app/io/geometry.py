"""Line geometry reference: GeoJSON LineStrings with km stations, in any declared CRS.

Accepted input (one feature per line and track)::

    {"type": "FeatureCollection",
     "crs": {"type": "name", "properties": {"name": "EPSG:25832"}},
     "features": [
       {"type": "Feature",
        "properties": {"line_id": "4010", "track": "1",
                       "km": [12.000, 12.250, 12.500, ...]},
        "geometry": {"type": "LineString",
                     "coordinates": [[512340.1, 5401200.4], [512560.9, 5401318.0], ...]}}]}

* ``crs`` (the GeoJSON 2008 member; any CRS pyproj knows: ``EPSG:31467``,
  ``urn:ogc:def:crs:EPSG::25832`` …) gives the coordinates' CRS; without it
  they are WGS84 longitude, latitude (RFC 7946).
* ``properties.km`` holds the line km (km) at every vertex, strictly
  increasing or strictly decreasing; between two vertices the km is linear in
  the distance. The stations must agree with the geometry's length within
  ``KM_LENGTH_TOLERANCE`` (catches metres given as km and a wrong CRS).

Coordinates are kept as WGS84 (lon, lat); map matching works in a local
azimuthal equidistant projection centred on the line
(:meth:`LineGeometry.polyline`, :meth:`LineGeometry.to_local`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from app.analysis.map_matching import Polyline
from app.core.i18n import _
from app.io.errors import RunFileError
from app.io.json_input import load_json

__all__ = [
    "LineGeometry",
    "parse_geojson",
    "KM_LENGTH_TOLERANCE",
    "MAX_FEATURES",
    "MAX_VERTICES",
]

#: Largest relative difference between the km stations' span and the geometric length.
KM_LENGTH_TOLERANCE = 0.05
#: Most features per file.
MAX_FEATURES = 1000
#: Most vertices per file.
MAX_VERTICES = 2_000_000
#: Deepest nesting of the document (a FeatureCollection's coordinates sit at level 6).
MAX_DEPTH = 16
#: Longest accepted CRS name or definition, characters.
MAX_CRS_CHARS = 2048
#: Semi-major axes of the Earth's ellipsoids and spheres, m (others: another body or no Earth).
_EARTH_SEMI_MAJOR_M = (6_350_000.0, 6_400_000.0)
_WGS84 = "EPSG:4326"


@dataclass(frozen=True)
class LineGeometry:
    """One track of a line: WGS84 vertices with km stations.

    Attributes
    ----------
    line_id, track : str
        Line and track ids (as in the run metadata).
    lon, lat : numpy.ndarray
        Vertex coordinates, WGS84 degrees.
    km : numpy.ndarray
        Line km at every vertex, km; strictly monotonic.
    source_crs : str
        CRS the file declared (``EPSG:4326`` when none).
    """

    line_id: str
    track: str
    lon: np.ndarray
    lat: np.ndarray
    km: np.ndarray
    source_crs: str = _WGS84
    _local: Any = field(default=None, init=False, repr=False, compare=False)
    _polyline: Polyline | None = field(default=None, init=False, repr=False, compare=False)

    def _transformer(self) -> Any:
        if self._local is None:
            from pyproj import Transformer

            lat0 = float(np.mean(self.lat))
            lon0 = float(np.mean(self.lon))
            proj = f"+proj=aeqd +lat_0={lat0:.9f} +lon_0={lon0:.9f} +datum=WGS84 +units=m"
            object.__setattr__(self, "_local", Transformer.from_crs(_WGS84, proj, always_xy=True))
        return self._local

    def to_local(self, lon: np.ndarray, lat: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Local metric coordinates (m) of WGS84 points (degrees)."""
        x, y = self._transformer().transform(np.asarray(lon, float), np.asarray(lat, float))
        return np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64)

    def from_local(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """WGS84 points (degrees) of local metric coordinates (m); inverse of :meth:`to_local`."""
        lon, lat = self._transformer().transform(
            np.asarray(x, float), np.asarray(y, float), direction="INVERSE"
        )
        return np.asarray(lon, dtype=np.float64), np.asarray(lat, dtype=np.float64)

    def polyline(self) -> Polyline:
        """The geometry in the local projection with chainage m (for map matching)."""
        if self._polyline is None:
            x, y = self.to_local(self.lon, self.lat)
            object.__setattr__(self, "_polyline", Polyline(x, y, 1000.0 * self.km))
        assert self._polyline is not None
        return self._polyline

    @property
    def length_m(self) -> float:
        """Geometric length, m (local projection)."""
        pl = self.polyline()
        return float(np.hypot(np.diff(pl.x), np.diff(pl.y)).sum())

    def lonlat_at_km(self, km: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """WGS84 points of the line at the given km (clamped to the line's ends)."""
        x, y = self.polyline().point_at(1000.0 * np.asarray(km, dtype=np.float64))
        return self.from_local(x, y)

    def to_feature(self) -> dict[str, Any]:
        """The geometry as a WGS84 GeoJSON feature."""
        return {
            "type": "Feature",
            "properties": {
                "line_id": self.line_id,
                "track": self.track,
                "km": [float(k) for k in self.km],
                "source_crs": self.source_crs,
            },
            "geometry": {
                "type": "LineString",
                "coordinates": [[float(a), float(b)] for a, b in zip(self.lon, self.lat, strict=True)],
            },
        }


def _crs_of(doc: Mapping[str, Any]) -> str:
    crs = doc.get("crs")
    if crs is None:
        return _WGS84
    name = None
    if isinstance(crs, Mapping):
        props = crs.get("properties")
        if isinstance(props, Mapping):
            name = props.get("name")
    elif isinstance(crs, str):
        name = crs
    if not isinstance(name, str) or not name.strip():
        raise RunFileError("crs", _('must be {"type": "name", "properties": {"name": "EPSG:…"}}'))
    if len(name) > MAX_CRS_CHARS or "\x00" in name:
        raise RunFileError("crs", _("must be a CRS name of at most {n} characters without NUL", n=MAX_CRS_CHARS))
    from pyproj import CRS, Transformer
    from pyproj.exceptions import CRSError, ProjError

    try:
        parsed = CRS.from_user_input(name.strip())
    except CRSError:
        raise RunFileError("crs", _("unknown CRS {name!r}", name=name[:80])) from None
    ellipsoid = parsed.ellipsoid
    axis = ellipsoid.semi_major_metre if ellipsoid is not None else None
    if not (parsed.is_geographic or parsed.is_projected) or parsed.is_compound or len(parsed.axis_info) != 2:
        raise RunFileError("crs", _("{name!r} is not a two-dimensional geographic or projected CRS (geocentric, vertical, compound and 3-D CRS are not accepted)", name=name[:80]))
    if axis is None or not _EARTH_SEMI_MAJOR_M[0] <= axis <= _EARTH_SEMI_MAJOR_M[1]:
        raise RunFileError("crs", _("{name!r} is not a CRS of the Earth (ellipsoid {ellipsoid!r})", name=name[:80], ellipsoid=getattr(ellipsoid, 'name', None)))
    try:
        Transformer.from_crs(parsed, _WGS84, always_xy=True)
    except (CRSError, ProjError) as exc:
        raise RunFileError("crs", _("{name!r} cannot be transformed to WGS84: {error}", name=name[:80], error=str(exc)[:200])) from None
    return parsed.to_string()


def _to_wgs84(crs: str, x: np.ndarray, y: np.ndarray, where: str) -> tuple[np.ndarray, np.ndarray]:
    if crs == _WGS84:
        return x, y
    from pyproj import Transformer
    from pyproj.exceptions import CRSError, ProjError

    try:
        lon, lat = Transformer.from_crs(crs, _WGS84, always_xy=True).transform(x, y)
    except (CRSError, ProjError) as exc:
        raise RunFileError(where, _("coordinates cannot be transformed from {crs} to WGS84: {error}", crs=crs, error=str(exc)[:200])) from None
    lon, lat = np.asarray(lon, dtype=np.float64), np.asarray(lat, dtype=np.float64)
    if not (np.isfinite(lon).all() and np.isfinite(lat).all()):
        raise RunFileError(where, _("coordinates cannot be transformed from {crs} to WGS84", crs=crs))
    return lon, lat


def _text(props: Mapping[str, Any], key: str, where: str) -> str:
    value = props.get(key)
    if isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value):
        value = str(value)
    if not isinstance(value, str) or not value.strip() or len(value) > 128:
        raise RunFileError(where, _("properties.{key} is missing (a non-empty text of ≤ 128 characters)", key=key))
    if "\x00" in value:
        raise RunFileError(where, _("properties.{key} must not contain NUL characters (\\u0000)", key=key))
    return value.strip()


def _number(value: Any) -> float:
    """A JSON number as a float (``TypeError`` for anything else, booleans included)."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise TypeError("not a number")
    return float(value)


def _feature(feat: Any, i: int, crs: str) -> LineGeometry:
    where = f"features[{i}]"
    if not isinstance(feat, Mapping) or feat.get("type") != "Feature":
        raise RunFileError(where, _("must be a GeoJSON Feature"))
    props = feat.get("properties")
    if not isinstance(props, Mapping):
        raise RunFileError(where, _("has no properties (line_id, track, km)"))
    line_id = _text(props, "line_id", where)
    track = _text(props, "track", where)
    label = _("line {line} track {track}", line=line_id, track=track)
    geom = feat.get("geometry")
    if not isinstance(geom, Mapping) or geom.get("type") != "LineString":
        raise RunFileError(where, _("({label}) geometry must be a LineString", label=label))
    coords = geom.get("coordinates")
    if not isinstance(coords, list) or len(coords) < 2:
        raise RunFileError(where, _("({label}) a LineString needs at least two positions", label=label))
    try:
        xy = np.array([[_number(p[0]), _number(p[1])] for p in coords], dtype=np.float64)
    except (TypeError, ValueError, IndexError, KeyError, OverflowError):
        raise RunFileError(where, _("({label}) coordinates must be [x, y] number pairs", label=label)) from None
    if not np.isfinite(xy).all():
        raise RunFileError(where, _("({label}) coordinates must be finite", label=label))
    km_raw = props.get("km")
    if km_raw is None:
        raise RunFileError(
            where,
            _("({label}) has no km stations: give properties.km, the line km at every vertex", label=label),
        )
    try:
        km = np.array([_number(k) for k in km_raw], dtype=np.float64)
    except (TypeError, ValueError, OverflowError):
        raise RunFileError(where, _("({label}) properties.km must be a list of numbers (km)", label=label)) from None
    if km.size != xy.shape[0]:
        raise RunFileError(
            where, _("({label}) properties.km has {stations} stations for {vertices} vertices", label=label, stations=km.size, vertices=xy.shape[0])
        )
    dk = np.diff(km)
    if not np.isfinite(km).all() or not ((dk > 0).all() or (dk < 0).all()):
        raise RunFileError(where, _("({label}) km stations must be strictly increasing or decreasing", label=label))
    import shapely

    line = shapely.LineString(xy)
    if not line.is_valid or line.length <= 0:
        raise RunFileError(where, _("({label}) invalid LineString: {reason}", label=label, reason=shapely.is_valid_reason(line)))
    if (np.hypot(*np.diff(xy, axis=0).T) <= 0).any():
        raise RunFileError(where, _("({label}) has two consecutive equal vertices", label=label))
    lon, lat = _to_wgs84(crs, xy[:, 0], xy[:, 1], where)
    if (np.abs(lat) > 90).any() or (np.abs(lon) > 180).any():
        raise RunFileError(where, _("({label}) coordinates are not longitude/latitude in {crs}", label=label, crs=crs))
    out = LineGeometry(line_id, track, lon, lat, km, crs)
    try:
        pl = out.polyline()
    except ValueError as exc:
        raise RunFileError(where, _("({label}) {error}", label=label, error=exc)) from None
    length = float(shapely.LineString(np.column_stack((pl.x, pl.y))).length)
    span = abs(float(km[-1] - km[0])) * 1000.0
    if abs(span - length) > KM_LENGTH_TOLERANCE * length:
        raise RunFileError(
            where,
            _("({label}) the km stations span {span:.0f} m but the geometry is {length:.0f} m long (more than {tolerance:g} % apart: km in metres, or a wrong CRS?)", label=label, span=span, length=length, tolerance=100 * KM_LENGTH_TOLERANCE),
        )
    return out


def parse_geojson(data: bytes | str | Mapping[str, Any]) -> list[LineGeometry]:
    """Read line geometries from GeoJSON (a FeatureCollection or one Feature).

    Parameters
    ----------
    data : bytes, str or mapping
        The document.

    Returns
    -------
    list of LineGeometry
        One per feature, in file order.

    Raises
    ------
    RunFileError
        ``field`` is ``file``, ``crs`` or ``features[i]`` (the message names
        the line and track); a feature without km stations, with too few or
        non-monotonic stations, or whose stations disagree with its length is
        refused, and so is a line and track given twice.
    """
    if isinstance(data, bytes | str):
        doc = load_json(data, field="file", max_depth=MAX_DEPTH)
    else:
        doc = data
    if not isinstance(doc, Mapping):
        raise RunFileError("file", _("GeoJSON must be an object"))
    if doc.get("type") == "Feature":
        features = [doc]
    elif doc.get("type") == "FeatureCollection" and isinstance(doc.get("features"), list):
        features = doc["features"]
    else:
        raise RunFileError("file", _("GeoJSON must be a FeatureCollection or a Feature"))
    if not features:
        raise RunFileError("file", _("no features"))
    if len(features) > MAX_FEATURES:
        raise RunFileError("file", _("{n_features} features exceed the limit of {limit}", n_features=len(features), limit=MAX_FEATURES))
    n_vertices = sum(
        len(f["geometry"]["coordinates"])
        for f in features
        if isinstance(f, Mapping) and isinstance(f.get("geometry"), Mapping)
        and isinstance(f["geometry"].get("coordinates"), list)
    )
    if n_vertices > MAX_VERTICES:
        raise RunFileError("file", _("{n_vertices} vertices exceed the limit of {limit}", n_vertices=n_vertices, limit=MAX_VERTICES))
    crs = _crs_of(doc)
    out: list[LineGeometry] = []
    seen: dict[tuple[str, str], int] = {}
    for i, feat in enumerate(features):
        geom = _feature(feat, i, crs)
        key = (geom.line_id, geom.track)
        if key in seen:
            raise RunFileError(
                f"features[{i}]",
                _("line {line} track {track} is also features[{index}]", line=key[0], track=key[1], index=seen[key]),
            )
        seen[key] = i
        out.append(geom)
    return out

