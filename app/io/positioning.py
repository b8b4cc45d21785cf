"""Where a run lies on the line: the three position kinds of an input file.

``relative``
    The position channel (or the speed integral) is the distance travelled
    since the start; ``km_start`` and ``km_increasing`` of the metadata place
    it on the line. A channel whose first sample is not 0 is still taken as
    relative (its first sample subtracted), and a warning says so.
``line_km``
    The position channel is the line chainage, m (line km × 1000), increasing
    or decreasing. The canonical file stores it as distance travelled (through
    the channel's calibration: ``±(chainage - first chainage)``) with
    ``km_start`` and ``km_increasing`` taken from it.
``gnss``
    ``lat``/``lon`` fixes are matched onto the line geometry of the run's line
    and track (:mod:`app.analysis.map_matching`) and fused with the odometry
    (:mod:`app.analysis.gnss_fusion`); the position channel is rewritten as the
    fused distance along the line and ``km_start``/``km_increasing`` derived.

Canonical files always hold a ``relative`` position.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from app.analysis.gnss_fusion import FusionSettings, fuse_odometry_gnss
from app.analysis.map_matching import match_points
from app.core.i18n import _
from app.io.canonical import CanonicalWriter
from app.io.errors import RunFileError
from app.io.geometry import LineGeometry
from app.io.limits import IngestLimits
from app.io.metadata import RunMetadata

__all__ = [
    "GeometryLookup",
    "CORRIDOR_M",
    "MAX_OUTSIDE_FRACTION",
    "FUSED_POSITION",
    "resolve_position_kind",
    "GnssFixes",
    "finish_line_km",
    "apply_gnss",
]

#: ``lookup(line_id, track)`` → the stored geometry of that line and track, or None.
GeometryLookup = Callable[[str, str], LineGeometry | None]
#: GNSS fixes farther than this from the line are outside its corridor, m.
CORRIDOR_M = 50.0
#: A run with more fixes than this fraction outside the corridor is refused.
MAX_OUTSIDE_FRACTION = 0.1
#: ``derived`` attribute of a position channel rewritten from GNSS.
FUSED_POSITION = "odometry fused with GNSS fixes map-matched onto the line geometry"


def resolve_position_kind(meta: RunMetadata, channels: list[str], warnings: list[str]) -> str:
    """The position kind of a run, checked against its metadata and channels.

    Parameters
    ----------
    meta : RunMetadata
        Merged input metadata.
    channels : list of str
        trackvkf channels of the input (``lat``/``lon`` included).
    warnings : list of str
        Appended to: GNSS channels present but not used.

    Returns
    -------
    str
        ``"relative"``, ``"line_km"`` or ``"gnss"``.

    Raises
    ------
    RunFileError
        ``km_start``/``km_increasing`` missing for ``relative`` or given for a
        kind that derives them; ``position`` missing for ``line_km``; ``lat``
        missing for ``gnss``.
    """
    gnss = "lat" in channels and "lon" in channels
    kind = meta.position_kind
    if kind is None:
        kind = "gnss" if gnss and meta.km_start is None else "relative"
    if kind == "relative":
        for name in ("km_start", "km_increasing"):
            if getattr(meta, name) is None:
                raise RunFileError(
                    name,
                    _("required field is missing (relative positions need the line km of the first sample and the km direction; or give position_kind line_km or GNSS channels)"),
                )
        if gnss:
            warnings.append(_(
                "lat/lon: GNSS channels not used (position_kind relative with km_start); "
                "give position_kind gnss to place the run by GNSS"
            ))
        return kind
    for name in ("km_start", "km_increasing"):
        if getattr(meta, name) is not None:
            raise RunFileError(
                name,
                _("not given with position_kind {kind}: the km comes from the position channel", kind=kind)
                if kind == "line_km" else
                _("not given with position_kind {kind}: the km comes from the GNSS fixes", kind=kind),
            )
    if kind == "line_km" and "position" not in channels:
        raise RunFileError(
            "position", _("position_kind line_km needs a position channel holding the line chainage (m)")
        )
    if kind == "gnss" and not gnss:
        raise RunFileError("lat", _("position_kind gnss needs lat and lon channels"))
    return kind


class GnssFixes:
    """GNSS fixes gathered block by block while a run is ingested (thinned to a rate).

    Parameters
    ----------
    fs : float
        Sample rate of the run, Hz.
    limits : IngestLimits
        ``max_gnss_rate_hz`` sets the thinning.
    """

    def __init__(self, fs: float, limits: IngestLimits) -> None:
        self.step = max(1, int(round(fs / limits.max_gnss_rate_hz)))
        self.fs = float(fs)
        self._idx: list[np.ndarray] = []
        self._lat: list[np.ndarray] = []
        self._lon: list[np.ndarray] = []

    def add(self, offset: int, lat: np.ndarray, lon: np.ndarray) -> None:
        """Take the fixes of a block starting at sample ``offset``."""
        first = (-offset) % self.step
        k = np.arange(first, lat.size, self.step)
        la, lo = lat[k], lon[k]
        ok = np.isfinite(la) & np.isfinite(lo)
        k, la, lo = k[ok], la[ok], lo[ok]
        for name, v, bound in (("lat", la, 90.0), ("lon", lo, 180.0)):
            bad = np.flatnonzero(np.abs(v) > bound)
            if bad.size:
                raise RunFileError(
                    name,
                    (_("{v:.6g} at sample {sample} is not a WGS84 latitude in degrees", v=v[bad[0]], sample=offset + int(k[bad[0]]))
                     if name == "lat" else
                     _("{v:.6g} at sample {sample} is not a WGS84 longitude in degrees", v=v[bad[0]], sample=offset + int(k[bad[0]]))),
                )
        self._idx.append(offset + k)
        self._lat.append(la)
        self._lon.append(lo)

    def arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Sample indices (int64), latitudes and longitudes (degrees) of the fixes."""
        if not self._idx:
            return np.zeros(0, dtype=np.int64), np.zeros(0), np.zeros(0)
        return np.concatenate(self._idx), np.concatenate(self._lat), np.concatenate(self._lon)


def finish_line_km(writer: CanonicalWriter, first_m: float | None, direction: int) -> None:
    """Turn a stored line-chainage position channel into a relative one.

    The stored raw values stay; the channel's calibration becomes
    ``±(gain · raw + offset − first)`` and the metadata gets ``km_start`` and
    ``km_increasing`` from the chainage.

    Raises
    ------
    RunFileError
        ``position`` when the chainage never changes (no km direction).
    """
    if first_m is None or direction == 0:
        raise RunFileError(
            "position", _("the line km channel never changes: the km direction cannot be told")
        )
    meta = writer.metadata
    gain, offset = meta.gain_offset("position")
    cal = dict(meta.calibration)
    cal["position"] = {"gain": direction * gain, "offset": direction * (offset - first_m)}
    writer.metadata = RunMetadata.model_validate(
        {
            **meta.model_dump(),
            "calibration": cal,
            "km_start": first_m / 1000.0,
            "km_increasing": direction > 0,
            "position_kind": "relative",
        }
    )
    ds = writer.h5["position"]
    ds.attrs["gain"] = float(direction * gain)
    ds.attrs["offset"] = float(direction * (offset - first_m))


def _read_position(writer: CanonicalWriter, a: int, b: int) -> np.ndarray:
    ds = writer.h5["position"]
    gain, offset = float(ds.attrs["gain"]), float(ds.attrs["offset"])
    return ds[a:b].astype(np.float64) * gain + offset


def apply_gnss(
    writer: CanonicalWriter,
    fixes: GnssFixes,
    geometry: LineGeometry | None,
    n: int,
    limits: IngestLimits,
    warnings: list[str],
    settings: FusionSettings | None = None,
) -> dict[str, Any]:
    """Place a run on the line by its GNSS fixes and rewrite its position channel.

    Parameters
    ----------
    writer : CanonicalWriter
        The canonical file being written; its ``position`` channel holds the
        odometry (measured or integrated from speed).
    fixes : GnssFixes
        The run's fixes.
    geometry : LineGeometry or None
        Geometry of the run's line and track.
    n : int
        Samples of the run.
    limits : IngestLimits
        ``block_samples`` bounds the memory of the rewrite.
    warnings : list of str
        Appended to: outages bridged, fixes outside the corridor.
    settings : FusionSettings, optional
        Fusion parameters.

    Returns
    -------
    dict
        The positioning report kept with the run.

    Raises
    ------
    RunFileError
        ``lat``: no geometry, too few fixes, more than
        :data:`MAX_OUTSIDE_FRACTION` of the fixes farther than
        :data:`CORRIDOR_M` from the line, or odometry and GNSS that disagree.
    """
    meta = writer.metadata
    label = _("line {line} track {track}", line=meta.line_id, track=meta.track)
    if geometry is None:
        raise RunFileError(
            "lat",
            _("GNSS positions need the line geometry of {label}, and none is stored; import it (POST /api/v1/geometry) or give km_start with position_kind relative", label=label),
        )
    idx, lat, lon = fixes.arrays()
    if idx.size == 0:
        raise RunFileError("lat", _("no GNSS fix in the run (lat/lon are NaN everywhere)"))
    odo = np.empty(idx.size)
    block = limits.block_samples
    for a in range(0, n, block):
        sel = np.flatnonzero((idx >= a) & (idx < a + block))
        if sel.size:
            odo[sel] = _read_position(writer, a, min(a + block, n))[idx[sel] - a]
    x, y = geometry.to_local(lon, lat)
    match = match_points(geometry.polyline(), x, y)
    far = np.abs(match.offset_m) > CORRIDOR_M
    n_far = int(far.sum())
    if n_far > MAX_OUTSIDE_FRACTION * idx.size:
        raise RunFileError(
            "lat",
            _("{n_far} of {n} GNSS fixes lie more than {corridor:g} m from the geometry of {label} (median distance {median:.0f} m): wrong line, track or geometry?", n_far=n_far, n=idx.size, corridor=CORRIDOR_M, label=label, median=float(np.median(np.abs(match.offset_m)))),
        )
    keep = ~far
    odo0 = float(_read_position(writer, 0, 1)[0])
    odo1 = float(_read_position(writer, n - 1, n)[0])
    try:
        fusion = fuse_odometry_gnss(
            odo[keep],
            match.chainage_m[keep],
            t_s=idx[keep] / fixes.fs,
            odo_range_m=(odo0, odo1),
            settings=settings,
        )
    except ValueError as exc:
        raise RunFileError("lat", _("GNSS cannot place the run on {label}: {error}", label=label, error=exc)) from None
    direction = fusion.direction
    c0 = float(fusion.chainage(np.array([odo0]))[0])
    ds = writer.h5["position"]
    for a in range(0, n, block):
        b = min(a + block, n)
        c = fusion.chainage(_read_position(writer, a, b))
        ds[a:b] = direction * (c - c0)
    ds.attrs["gain"] = 1.0
    ds.attrs["offset"] = 0.0
    ds.attrs["derived"] = FUSED_POSITION
    cal = {k: v for k, v in meta.calibration.items() if k != "position"}
    writer.metadata = RunMetadata.model_validate(
        {
            **meta.model_dump(),
            "calibration": cal,
            "km_start": c0 / 1000.0,
            "km_increasing": direction > 0,
            "position_kind": "relative",
        }
    )
    if fusion.outages:
        longest = max(b - a for a, b in fusion.outages)
        warnings.append(_("lat/lon: {n} GNSS outage(s) bridged by the odometry (longest {longest:.1f} s)",
                          n=len(fusion.outages), longest=longest))
    if n_far:
        warnings.append(_("lat/lon: {n_far} GNSS fixes more than {corridor:g} m from the line were not used",
                          n_far=n_far, corridor=CORRIDOR_M))
    return {
        "km_source": "gnss",
        "geometry": {"line_id": geometry.line_id, "track": geometry.track},
        "corridor_m": CORRIDOR_M,
        "fixes_outside_corridor": n_far,
        "fusion": fusion.summary(),
    }
