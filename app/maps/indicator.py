"""A profile quantity of a run along its line's geometry: the mean over the bins and wheels of each
segment, placed (WGS84 and local metres) at the segment's centre on the line.

Segments without profile rows have the value None; a quantity that is not a profile column of
:data:`INDICATOR_UNITS` answers 422 naming ``quantity``. ``stiffness_index`` is the run's stiffness
index ln(A / A_ref(class, v)) by the line's reference curves (what the pages show first), the
others are stored profile columns.
"""

from __future__ import annotations

import numpy as np

from app.analytics.frames import load_profiles, select_runs
from app.analytics.stiffness_index import index_context
from app.core.errors import ApiError, not_found
from app.core.i18n import _
from app.core.jsonable import finite_or_none
from app.db import crud, recorder_crud, results_reader
from app.db.models import PROFILE_VALUE_COLUMNS
from app.db.session import Database
from app.io.channels import UNITS
from app.settings import Settings

__all__ = ["STIFFNESS_INDEX", "INDICATOR_UNITS", "DEFAULT_MAP_SEGMENT_M", "segment_means", "geometry_indicator"]

#: Default segment length of the map's indicator along a line, m.
DEFAULT_MAP_SEGMENT_M = 100.0

#: The stiffness index: computed from the run's amplitude and speed by the reference curves.
STIFFNESS_INDEX = "stiffness_index"
#: Quantities the map can colour the line by (the stiffness index, profile columns) and their units.
INDICATOR_UNITS: dict[str, str] = {
    STIFFNESS_INDEX: "ln units",
    **{c: UNITS["Z11"] for c in PROFILE_VALUE_COLUMNS if c.startswith(("sleeper_amp", "order_amp", "residual"))},
    "speed_mean": UNITS["speed"],
    "sleeper_force_amp": UNITS["Q11"],
    "track_impact_mm": "mm",
}


def segment_means(km: np.ndarray, values: np.ndarray, km_range: tuple[float, float],
                  segment_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Segment edges (km) of ``segment_m`` over ``km_range`` and the mean of the finite ``values`` per
    segment (NaN where none)."""
    lo, hi = sorted(km_range)
    edges = np.arange(lo * 1000.0, hi * 1000.0 + segment_m, segment_m) / 1000.0
    edges = edges[edges <= hi + 1e-9]
    if edges.size < 2:
        edges = np.array([lo, hi])
    n = edges.size - 1
    means = np.full(n, np.nan)
    if km.size:
        k = np.searchsorted(edges, km, side="right") - 1
        ok = (k >= 0) & (k < n) & np.isfinite(values)
        sums = np.bincount(k[ok], weights=values[ok], minlength=n)
        counts = np.bincount(k[ok], minlength=n)
        with np.errstate(invalid="ignore", divide="ignore"):
            means = np.where(counts > 0, sums / np.maximum(counts, 1), np.nan)
    return edges, means


def _index_rows(db: Database, settings: Settings, run_id: int, line_id: str, track: str) -> tuple[np.ndarray, np.ndarray]:
    """(km, stiffness index) of the bins of a run with amplitude and speed (the analytics' frame)."""
    sel = select_runs(db, line_id, track, [run_id])
    df = load_profiles(db, settings, sel)
    if df.empty:
        return np.zeros(0), np.zeros(0)
    df = index_context(db, settings, sel.line_id, sel.track, sel.bin_length).add_columns(df)
    return df["km"].to_numpy(dtype=np.float64), df["stiffness_index"].to_numpy(dtype=np.float64)


def geometry_indicator(db: Database, geometry_id: int, *, quantity: str, run_id: int | None,
                       segment_m: float, settings: Settings | None = None) -> dict:
    """``quantity`` of ``run_id`` (default: the latest processed run of the geometry's line and
    track) per segment of the line, placed on it."""
    if quantity not in INDICATOR_UNITS:
        raise ApiError(422, "quantity", _("unknown quantity {quantity}; one of {choices}", quantity=repr(quantity), choices=', '.join(INDICATOR_UNITS)))
    with db.read() as session:
        row = recorder_crud.get_geometry(session, geometry_id)
        if row is None:
            raise not_found("geometry", geometry_id)
        geom = recorder_crud.to_line_geometry(row)
        if run_id is None:
            run = recorder_crud.latest_processed_run(session, row.line_id, row.track)
        else:
            run = crud.get_run(session, run_id)
            if run is None:
                raise not_found("run", run_id)
            if (run.line_id, run.track) != (row.line_id, row.track):
                raise ApiError(422, "run_id", _("run {run_id} is on line {line_id} track {track}", run_id=run_id, line_id=run.line_id, track=run.track))
        frame = None
        if run is not None and quantity != STIFFNESS_INDEX:
            frame = results_reader.profile_rows(session, run.id, columns=[quantity])
    if run is not None and quantity == STIFFNESS_INDEX:
        km, v = _index_rows(db, settings or Settings(), run.id, row.line_id, row.track)
    else:
        has_rows = frame is not None and len(frame)
        km = frame["km"].to_numpy(dtype=np.float64) if has_rows else np.zeros(0)
        v = frame[quantity].to_numpy(dtype=np.float64) if has_rows else np.zeros(0)
    edges, values = segment_means(km, v, (float(geom.km[0]), float(geom.km[-1])), segment_m)
    centres = 0.5 * (edges[:-1] + edges[1:])
    lon, lat = geom.lonlat_at_km(centres)
    x, y = geom.to_local(lon, lat)
    segments = [
        {"km_from": float(a), "km_to": float(b), "km": float(c), "value": finite_or_none(val),
         "lon": float(lo_), "lat": float(la), "x_m": float(xx), "y_m": float(yy)}
        for a, b, c, val, lo_, la, xx, yy in zip(edges[:-1], edges[1:], centres, values, lon, lat, x, y, strict=True)
    ]
    return {"geometry_id": geometry_id, "line_id": row.line_id, "track": row.track,
            "run_id": run.id if run is not None else None, "quantity": quantity,
            "unit": INDICATOR_UNITS[quantity], "segment_m": segment_m, "segments": segments}
