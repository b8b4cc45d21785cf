"""Asset files (CSV or GeoJSON) → validated rows; pure (bytes in, dicts out).

CSV: header ``line_id,track,type,km[,km_to,name]`` (``line`` is read as ``line_id``; extra
columns are ignored; an empty ``track`` puts the asset on every track of its line).
GeoJSON: a FeatureCollection whose features carry the same names as properties; a Point
geometry gives the asset's ``lon``/``lat``, a LineString its middle vertex; ``null``
geometry is allowed (the km is what places are matched on).

Types: :data:`app.analysis.condition.discontinuities.ASSET_TYPES` (case, spaces and hyphens
are normalised: "Level crossing" → ``level_crossing``). ``km_to`` must not be below ``km``.
Every error raises :class:`~app.io.errors.RunFileError` naming the row (CSV, 1 = first data
row) or the feature (GeoJSON, 1 = first feature) and the column/property: nothing is imported
from a file with one bad value.
"""

from __future__ import annotations

import csv
import io
import json
import math
from typing import Any

from app.analysis.condition.discontinuities import ASSET_TYPES
from app.assets.limits import MAX_ASSETS
from app.core.i18n import _
from app.io.errors import RunFileError

__all__ = ["MAX_ASSETS", "ASSET_TYPES", "read_assets"]

_KM_BOUND = 100_000.0
_MAX_TEXT = {"line_id": 128, "track": 64, "type": 64, "name": 200}
_REQUIRED = ("line_id", "track", "type", "km")


def _where(kind: str, i: int, col: str) -> str:
    return f"{kind} {i}, {'column' if kind == 'row' else 'property'} {col}"


def _text(v: Any, where: str, col: str, required: bool) -> str | None:
    if v is None or (isinstance(v, float) and math.isnan(v)):
        s = ""
    elif isinstance(v, bool) or not isinstance(v, str | int | float):
        raise RunFileError(where, _("must be text, got {kind}", kind=type(v).__name__))
    elif isinstance(v, float) and v.is_integer():
        s = str(int(v))
    else:
        s = str(v).strip()
    if required and not s:
        raise RunFileError(where, _("is empty"))
    if len(s) > _MAX_TEXT[col]:
        raise RunFileError(where, _("is longer than {n} characters", n=_MAX_TEXT[col]))
    if "\x00" in s:
        raise RunFileError(where, _("must not contain NUL characters (\\u0000)"))
    return s or None


def _number(v: Any, where: str, required: bool, bound: float = _KM_BOUND) -> float | None:
    if v is None or (isinstance(v, str) and not v.strip()):
        if required:
            raise RunFileError(where, _("is empty"))
        return None
    if isinstance(v, bool):
        raise RunFileError(where, _("{value} is not a number", value=repr(v)))
    try:
        x = float(v.strip() if isinstance(v, str) else v)
    except OverflowError:  # an integer too large for a float (e.g. 400 digits of JSON)
        raise RunFileError(where, _("is not a finite number within ±{bound}", bound=format(bound, "g"))) from None
    except (TypeError, ValueError):
        raise RunFileError(where, _("{value} is not a number", value=repr(v))) from None
    if not math.isfinite(x) or abs(x) > bound:
        raise RunFileError(where, _("{value} is not a finite number within ±{bound}", value=repr(v), bound=format(bound, "g")))
    return x


def _type(v: Any, where: str) -> str:
    s = _text(v, where, "type", True) or ""
    t = s.lower().replace(" ", "_").replace("-", "_")
    if t not in ASSET_TYPES:
        raise RunFileError(where, _("{value} is not one of {choices}", value=repr(s), choices=", ".join(ASSET_TYPES)))
    return t


def _row(get: Any, kind: str, i: int) -> dict[str, Any]:
    w = lambda col: _where(kind, i, col)  # noqa: E731
    row = {
        "line_id": _text(get("line_id"), w("line_id"), "line_id", True),
        "track": _text(get("track"), w("track"), "track", False),
        "type": _type(get("type"), w("type")),
        "km": _number(get("km"), w("km"), True),
        "km_to": _number(get("km_to"), w("km_to"), False),
        "name": _text(get("name"), w("name"), "name", False),
        "lon": None,
        "lat": None,
    }
    if row["km_to"] is not None and row["km_to"] < row["km"]:
        raise RunFileError(w("km_to"), _("{km_to} is below km {km}", km_to=format(row["km_to"], "g"), km=format(row["km"], "g")))
    return row


def _read_csv(data: bytes) -> list[dict[str, Any]]:
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise RunFileError("file", _("is not UTF-8 text: {error}", error=exc)) from None
    reader = csv.reader(io.StringIO(text, newline=""))
    try:
        header = next(reader)
    except StopIteration:
        raise RunFileError("file", _("is empty")) from None
    except csv.Error as exc:
        raise RunFileError("file", _("cannot read the file as CSV: {error}", error=exc)) from None
    names = [{"line": "line_id"}.get(h.strip().lower(), h.strip().lower()) for h in header]
    missing = [c for c in _REQUIRED if c not in names]
    if missing:
        raise RunFileError(f"column {missing[0]}", _("is missing (header needed: {header})", header="line_id,track,type,km[,km_to,name]"))
    pos = {c: names.index(c) for c in (*_REQUIRED, "km_to", "name") if c in names}
    rows = []
    try:
        for i, rec in enumerate(reader, start=1):
            if not any(x.strip() for x in rec):
                continue
            if i > MAX_ASSETS:
                raise RunFileError("file", _("holds more than {n} assets", n=MAX_ASSETS))
            if len(rec) < len(names):
                rec = rec + [""] * (len(names) - len(rec))
            rows.append(_row(lambda c, rec=rec: rec[pos[c]] if c in pos else None, "row", i))
    except csv.Error as exc:
        raise RunFileError("file", _("cannot read the file as CSV: {error}", error=exc)) from None
    return rows


def _lon_lat(geom: Any, where: str) -> tuple[float | None, float | None]:
    if geom is None:
        return None, None
    if not isinstance(geom, dict):
        raise RunFileError(where, _("must be a GeoJSON geometry object or null"))
    kind, coords = geom.get("type"), geom.get("coordinates")
    try:
        if kind == "Point":
            pt = coords
        elif kind == "LineString" and isinstance(coords, list) and coords:
            pt = coords[len(coords) // 2]
        else:
            raise RunFileError(where, _("must be a Point or a LineString, got {kind}", kind=repr(kind)))
        lon, lat = float(pt[0]), float(pt[1])
    except (TypeError, ValueError, IndexError, KeyError, OverflowError):
        raise RunFileError(where, _("has no valid coordinates [lon, lat]")) from None
    if not (math.isfinite(lon) and math.isfinite(lat) and -180 <= lon <= 180 and -90 <= lat <= 90):
        raise RunFileError(where, _("coordinates ({lon}, {lat}) are not WGS84 lon/lat in degrees", lon=lon, lat=lat))
    return lon, lat


def _read_geojson(data: bytes) -> list[dict[str, Any]]:
    try:
        doc = json.loads(data)
    except (ValueError, RecursionError) as exc:
        raise RunFileError("file", _("is not valid JSON: {error}", error=exc)) from None
    if not isinstance(doc, dict) or doc.get("type") != "FeatureCollection" or not isinstance(doc.get("features"), list):
        raise RunFileError("file", _("must be a GeoJSON FeatureCollection with a features list"))
    feats = doc["features"]
    if len(feats) > MAX_ASSETS:
        raise RunFileError("file", _("holds more than {n} assets", n=MAX_ASSETS))
    rows = []
    for i, f in enumerate(feats, start=1):
        if not isinstance(f, dict) or not isinstance(f.get("properties"), dict):
            raise RunFileError(f"feature {i}", _("must be a Feature with a properties object"))
        props = f["properties"]
        row = _row(props.get, "feature", i)
        row["lon"], row["lat"] = _lon_lat(f.get("geometry"), f"feature {i}, geometry")
        rows.append(row)
    return rows


def read_assets(data: bytes, filename: str | None = None) -> list[dict[str, Any]]:
    """Parse and validate an asset file.

    Parameters
    ----------
    data : bytes
        The file (CSV, or GeoJSON: a ``.geojson``/``.json`` name or content starting with ``{``).
    filename : str, optional
        The upload's name.

    Returns
    -------
    list of dict
        ``line_id, track (None: every track), type, km, km_to, name, lon, lat`` per asset.

    Raises
    ------
    RunFileError
        ``field`` names the row/feature and the column/property, or ``file``.
    """
    if not data:
        raise RunFileError("file", _("is empty"))
    name = (filename or "").lower()
    is_json = name.endswith((".geojson", ".json")) or data.lstrip()[:1] == b"{"
    rows = _read_geojson(data) if is_json else _read_csv(data)
    if not rows:
        raise RunFileError("file", _("has no assets"))
    return rows
